"""The checks behind every way of building a :class:`diagnosers.Episode` (issue 32).

One mechanism for three doors: the constructor, ``Episode.from_frame`` and
``Episode.from_dataset`` all pass their measurements through :func:`real_values` and their labels
through the constraint table :data:`LABELS`, and :func:`read_dataset_episodes` is the one
validated reader of ``python -m fcc_env.generate`` files. Nothing is converted silently: booleans,
times and complex numbers are refused (a cast would turn them into numbers that mean something
else), and every message names the bad value, where it is (file, column or channel, row) and what
is allowed.
"""

from __future__ import annotations

import math
import numbers
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from diagnosers.episode.units import sidecar_units
from fcc_common.io import read_columns, read_header
from fcc_common.validation import Constraint, Integer, Real, check, invalid

__all__ = [
    "LABELS",
    "SAMPLE_TIME",
    "TIME_TOLERANCE_S",
    "Text",
    "check_channels",
    "check_labels",
    "frame_values",
    "read_dataset_episodes",
    "real_values",
]

#: Allowed sample periods: any positive duration (the simulator's own range is narrower).
SAMPLE_TIME = Real(0.0, math.inf, closed="neither", unit="s")
#: How far ``time_s`` may stray from ``k * sample_time_s``: the writer prints it with one
#: decimal (``%.1f``), so each value carries up to 0.05 s of rounding, the first one too.
TIME_TOLERANCE_S = 0.1
_INDEX = ("episode", "seed", "k", "time_s")


class Text(Constraint):
    """A ``str``; returns it unchanged."""

    def __init__(self, why: str | None = None) -> None:
        self.why = why

    def describe(self) -> str:
        return "text (a string)"

    def coerce(self, name: str, value: Any) -> str:
        if not isinstance(value, str):
            raise invalid(name, value, self.describe(), self.why)
        return value


#: The labels of an episode and their allowed forms (the onset's upper end depends on the length,
#: see :func:`check_labels`).
LABELS: dict[str, tuple[Constraint | None, ...]] = {
    "sample_time_s": (SAMPLE_TIME,),
    "fault_onset": (Integer(0), None),
    "seed": (Integer(), None),
    "scenario": (Text(),),
}


def check_labels(n_samples: int, **labels: Any) -> None:
    """Refuse a label of an ``n_samples`` episode outside :data:`LABELS` (values stay as given)."""
    for name, value in labels.items():
        cons = LABELS[name]
        if name == "fault_onset":
            cons = (Integer(0, n_samples - 1, why="a sample of the episode"), None)
        try:
            check(name, value, *cons)
        except ValueError as e:
            raise ValueError(f"Episode {e}") from None


def check_channels(channels: Any) -> tuple[str, ...]:
    """``channels`` as a tuple of distinct names; a single string is refused, not split."""
    ch = channels
    if (
        not isinstance(ch, Sequence)
        or isinstance(ch, str | bytes)
        or not all(isinstance(c, str) for c in ch)
    ):
        raise ValueError(
            f"Episode channels={ch!r} is outside the allowed range: a sequence of channel "
            "names, e.g. ('T_rx', 'T_rg1'), not one string"
        )
    allowed = "a non-empty sequence of distinct channel names"
    if len(ch) == 0:
        raise invalid("channels", ch, allowed)
    twice = sorted({c for c in ch if list(ch).count(c) > 1})
    if twice:
        raise invalid("channels", ch, allowed, f"{twice} appear more than once")
    return tuple(ch)


def _as_array(values: Any, name: str, where: str) -> np.ndarray:
    try:
        return np.asarray(values)
    except ValueError as e:  # numpy's "inhomogeneous shape": rows of different lengths
        lengths = [len(r) if hasattr(r, "__len__") else 1 for r in values]
        row = next((i for i, n in enumerate(lengths) if n != lengths[0]), None)
        what = f"row {row} has {lengths[row]} values, row 0 has {lengths[0]}" if row else str(e)
        raise ValueError(
            f"{where}{name} is ragged: {what}; allowed: a 2-D array (n_samples, n_channels)"
        ) from e


def _real_or_none(v: Any) -> float | None:
    """``float(v)`` for a real number or numeric text, else ``None`` (bools and complex too)."""
    if isinstance(v, str | bytes):
        try:
            return float(v)
        except ValueError:
            return None
    if isinstance(v, bool | np.bool_) or not isinstance(v, numbers.Real):
        return None
    return float(v)


_KIND_NAMES = {"b": "boolean", "M": "datetime64", "m": "timedelta64", "V": "structured"}


def real_values(
    values: Any,
    channels: tuple[str, ...],
    *,
    name: str = "y",
    where: str = "Episode ",
    row_word: str = "row",
) -> np.ndarray:
    """``values`` as a finite float array ``(n_samples, len(channels))``, or a ValueError naming
    the channel, the row (``row_word`` and its index) and the value, after the prefix ``where``.

    A float64 array comes back as it is (no copy); integers and numeric text convert exactly as
    ``np.asarray(values, dtype=np.float64)`` would.
    """
    arr = _as_array(values, name, where)
    if arr.ndim != 2 or arr.shape[1] != len(channels):
        raise ValueError(
            f"{where.rstrip()}.{name} must have shape (n_samples, {len(channels)}) to match "
            f"channels {channels}; got {arr.shape}"
        )
    if arr.shape[0] == 0:
        raise ValueError(
            f"{where}{name} has no samples (shape {arr.shape}); allowed: at least one row"
        )
    kind = arr.dtype.kind
    if kind in _KIND_NAMES:
        raise ValueError(
            f"{where}{name} holds {_KIND_NAMES[kind]} values (dtype {arr.dtype}); allowed: real "
            "numbers (int or float), never cast from booleans or times"
        )

    def refuse(r: int, j: int, why: str) -> ValueError:
        v = arr[r, j]
        v = v.item() if isinstance(v, np.generic) else v  # 'ten', not np.str_('ten')
        head = f"{where}channel {channels[j]!r}, {row_word} {r}: "
        return ValueError(head + str(invalid(name, v, "a real number", why)))

    if kind == "c":
        bad = np.argwhere(arr.imag != 0)
        r, j = bad[0] if len(bad) else (0, 0)
        raise refuse(r, j, "complex values are refused: the cast would drop the imaginary part")
    if kind in "OUS":  # one Python object per value: find the first that is not a number
        flat = [_real_or_none(v) for v in arr.ravel()]
        if None in flat:
            r, j = divmod(flat.index(None), arr.shape[1])
            raise refuse(r, j, "channels must hold numbers")
        y = np.asarray(flat, dtype=np.float64).reshape(arr.shape)
    else:
        y = np.asarray(arr, dtype=np.float64)
    bad = ~np.isfinite(y)
    if bad.any():
        r, j = np.argwhere(bad)[0]
        head = f"{where}channel {channels[j]!r}, {row_word} {r}: "
        raise ValueError(
            head
            + str(
                invalid(
                    name,
                    float(y[r, j]),
                    "a finite real number",
                    f"{int(bad.sum())} non-finite value(s) in all; clean or drop those samples",
                )
            )
        )
    return y


def frame_values(df: Any, channels: Sequence[str] | None) -> tuple[tuple[str, ...], np.ndarray]:
    """``(channel names, float array)`` of a pandas ``DataFrame``, checked column by column (a
    frame's columns each have their own type)."""
    names = tuple(str(c) for c in df.columns) if channels is None else check_channels(channels)
    missing = [c for c in names if c not in df.columns]
    if missing:
        raise ValueError(
            f"channels {missing} are not columns of the frame. Columns: {list(df.columns)}"
        )
    names = check_channels(names)
    twice = sorted({c for c in names if list(df.columns).count(c) > 1})
    if twice:
        raise ValueError(
            f"DataFrame columns {twice} appear more than once among {list(df.columns)}; "
            "allowed: each channel once (rename the copies)"
        )
    cols = []
    for c in names:
        col = df[c]
        if col.dtype.kind in "iuf":  # nullable integers: a missing value becomes NaN, refused below
            arr = col.to_numpy(dtype=np.float64, na_value=np.nan)
        elif col.dtype.kind in "bMm":
            raise ValueError(
                f"DataFrame channel {c!r} holds {col.dtype} values; allowed: real numbers "
                "(int or float), never cast from booleans or times"
            )
        else:
            arr = col.to_numpy()
        cols.append(real_values(arr[:, None], (c,), where="DataFrame "))
    return names, np.column_stack(cols)


# ---- the dataset reader ------------------------------------------------------------------------
def read_dataset_episodes(path: str | os.PathLike) -> list[dict[str, Any]]:
    """The checked episodes of a ``python -m fcc_env.generate`` dataset, as ``Episode`` keywords.

    Beyond the types, the rows must agree with the sidecar and with each other: the ``episode``
    column holds whole numbers in consecutive blocks, each of one ``seed``; ``time_s`` rises by
    ``sample_time_s`` per row (within :data:`TIME_TOLERANCE_S`) and ``k`` by one; the per-episode
    sidecar lists have one entry per episode of the file and the seeds agree with the data.
    """
    from fcc_env.generate import read_sidecar  # local: diagnosers works without the env

    p = Path(path)
    side = f"sidecar {str(p.with_suffix('.json'))!r}"
    where = f"dataset {str(p)!r}"
    meta = read_sidecar(p)  # refuses a missing, non-UTF-8 or foreign sidecar by name
    measured = _measured(meta, side)
    # a closed-loop file (FCC-closedloop-v0) adds what the control system records: the valve
    # command (manipulated) and the set points, after Table 1 as the env observes them
    recorded = [
        c
        for role in ("manipulated", "setpoint")
        for c in _role_list(meta, role, side)
        if c not in measured
    ]
    channels = measured + tuple(recorded)
    header = read_header(p)
    missing = [c for c in channels if c not in header]
    if missing:
        raise ValueError(
            f"{where}: the sidecar's roles.measured must name columns of the CSV; got "
            f"{list(channels)}, missing {missing}, columns {sorted(header)}"
        )
    if meta.get("sample_time_s") is None:
        raise ValueError(f"{where}: the sidecar has no sample_time_s; add it (in seconds)")
    dt = _sidecar(side, "sample_time_s", meta["sample_time_s"], SAMPLE_TIME)
    scenario = _sidecar(side, "scenario", meta.get("scenario"), Text(), None)
    n_declared = _sidecar(side, "n_samples", meta.get("n_samples"), Integer(1), None)
    clean = [f"clean_{c}" for c in measured]
    clean = clean if all(c in header for c in clean) else []
    index = [c for c in _INDEX if c in header]
    wanted = index + list(channels) + clean
    _, table = read_columns(p, wanted)
    if table.shape[0] == 0:
        raise ValueError(f"{where} has no data rows; allowed: at least one sample per episode")
    col = {n: table[:, j] for j, n in enumerate(wanted)}
    for n in ("episode", "seed", "k"):
        if n in col:
            _whole_numbers(col[n], n, where)
    key = next((k for k in ("episode", "seed") if k in col), None)
    blocks = _blocks(col[key], key, where) if key else [(0, 0, table.shape[0])]
    seeds = [_check_rows(col, ep_id, lo, hi, dt, where) for ep_id, lo, hi in blocks]
    if n_declared is not None:
        for ep_id, lo, hi in blocks:
            if hi - lo != n_declared:
                raise ValueError(
                    f"{where}: episode {ep_id:g} has {hi - lo} rows (data rows {lo}-{hi - 1}); "
                    f"allowed: the sidecar's n_samples={n_declared} rows per episode"
                )
    lists = {
        name: _episode_list(side, meta, name, len(blocks))
        for name in ("seeds", "scenarios", "fault_onsets", "terminated_at")
    }
    at = {"where": f"{where}: ", "row_word": "data row"}
    n_ch = len(index) + len(channels)
    y = real_values(table[:, len(index) : n_ch], channels, **at)
    y_clean = real_values(table[:, n_ch:], tuple(clean), name="y_clean", **at) if clean else None
    if y_clean is not None and recorded:  # the recorded command and set points carry no noise
        y_clean = np.hstack([y_clean, y[:, len(measured) :]])
    units = sidecar_units(meta, channels, side)
    out = []
    for i, ((ep_id, lo, hi), seed) in enumerate(zip(blocks, seeds, strict=True)):
        n = hi - lo
        s_seed = _sidecar(side, f"seeds[{i}]", lists["seeds"][i], Integer(), None)
        if s_seed is not None and seed is not None and s_seed != seed:
            raise ValueError(
                f"{side}: "
                + str(
                    invalid(
                        f"seeds[{i}]",
                        s_seed,
                        f"{seed}, the 'seed' column of episode {ep_id:g} in {where}",
                    )
                )
            )
        within = Integer(1, n, why=f"episode {i} has {n} rows")
        term = _sidecar(side, f"terminated_at[{i}]", lists["terminated_at"][i], within, None)
        onset = _sidecar(side, f"fault_onsets[{i}]", lists["fault_onsets"][i], Integer(0), None)
        scen = _sidecar(side, f"scenarios[{i}]", lists["scenarios"][i], Text(), None)
        n_used = n if term is None else term
        rows = slice(lo, lo + n_used)
        out.append(
            {
                # one contiguous array per episode, not a view that keeps the whole table
                "y": np.ascontiguousarray(y[rows]),
                "channels": channels,
                "sample_time_s": dt,
                "fault_onset": None if onset is None or onset >= n_used else onset,
                "scenario": scen or scenario or "unknown",
                "seed": s_seed if s_seed is not None else seed,
                "y_clean": None if y_clean is None else np.ascontiguousarray(y_clean[rows]),
                "units": units,
            }
        )
    return out


def _sidecar(side: str, name: str, value: Any, *constraints: Constraint | None) -> Any:
    try:
        return check(name, value, *constraints)
    except ValueError as e:
        raise ValueError(f"{side}: {e}") from None


def _measured(meta: dict[str, Any], side: str) -> tuple[str, ...]:
    roles = meta.get("roles", {})
    if not isinstance(roles, dict):
        raise ValueError(
            f"{side}: "
            + str(invalid("roles", roles, "a mapping of column roles, e.g. {'measured': [...]}"))
        )
    measured = roles.get("measured")
    allowed = "a non-empty list of distinct column names (not one string)"
    if not isinstance(measured, list) or not measured:
        raise ValueError(f"{side}: " + str(invalid("roles.measured", measured, allowed)))
    if not all(isinstance(c, str) for c in measured):
        raise ValueError(
            f"{side}: " + str(invalid("roles.measured", measured, allowed, "names are text"))
        )
    twice = sorted({c for c in measured if measured.count(c) > 1})
    if twice:
        why = f"{twice} appear more than once"
        raise ValueError(f"{side}: " + str(invalid("roles.measured", measured, allowed, why)))
    return tuple(measured)


def _role_list(meta: dict[str, Any], role: str, side: str) -> list[str]:
    """The columns of an optional role (``manipulated``, ``setpoint``): a list of names."""
    value = meta.get("roles", {}).get(role, [])
    if not isinstance(value, list) or not all(isinstance(c, str) for c in value):
        allowed = "a list of column names (not one string)"
        raise ValueError(f"{side}: " + str(invalid(f"roles.{role}", value, allowed)))
    return value


def _episode_list(side: str, meta: dict[str, Any], name: str, n_episodes: int) -> list[Any]:
    """A per-episode sidecar list, one entry per episode of the file (``None`` each if absent)."""
    value = meta.get(name)
    if value is None:
        return [None] * n_episodes
    if not isinstance(value, list) or len(value) != n_episodes:
        allowed = f"a list of {n_episodes} entries, one per episode"
        raise ValueError(
            f"{side}: "
            + str(invalid(name, value, allowed, f"the data holds {n_episodes} episodes"))
        )
    return value


def _whole_numbers(values: np.ndarray, name: str, where: str) -> None:
    bad = ~np.isfinite(values) | (values != np.round(values))
    if bad.any():
        r = int(np.argmax(bad))
        raise ValueError(
            f"{where}: column {name!r}, data row {r}: "
            + str(invalid(name, float(values[r]), "a whole number"))
        )


def _blocks(ids: np.ndarray, key: str, where: str) -> list[tuple[float, int, int]]:
    """``(id, first row, end row)`` of each episode; an id that comes back is a splice."""
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    ends = np.r_[starts[1:], len(ids)]
    seen: set[float] = set()
    for b, s in enumerate(starts):
        e = float(ids[s])
        if e in seen:
            raise ValueError(
                f"{where}: column {key!r}, data row {s}: episode {e:g} appears again after "
                f"episode {float(ids[starts[b - 1]]):g}; allowed: the rows of each episode "
                "consecutive, in one block"
            )
        seen.add(e)
    return [(float(ids[s]), int(s), int(e)) for s, e in zip(starts, ends, strict=True)]


def _check_rows(
    col: dict[str, np.ndarray], ep_id: float, lo: int, hi: int, dt: float, where: str
) -> int | None:
    """Check the index columns of one episode's rows; returns its seed (``None`` if no column)."""
    seed = None
    if "seed" in col:
        s = col["seed"][lo:hi]
        if (s != s[0]).any():
            r = int(np.argmax(s != s[0]))
            raise ValueError(
                f"{where}: column 'seed', data row {lo + r}: episode {ep_id:g} holds seeds "
                f"{sorted(int(v) for v in set(s.tolist()))} (seed {int(s[0])} until data row "
                f"{lo + r - 1}, then {int(s[r])}); allowed: one seed per episode (two episodes "
                "spliced under one id?)"
            )
        seed = int(s[0])
    if "time_s" in col:
        _check_time(col["time_s"][lo:hi], lo, dt, where)
    if "k" in col:
        k = col["k"][lo:hi]
        off = np.flatnonzero(k - k[0] != np.arange(hi - lo))
        if off.size:
            j = int(off[0])
            raise ValueError(
                f"{where}: column 'k', data row {lo + j}: k={k[j]:g} follows k={k[j - 1]:g}; "
                "allowed: k rising by 1 per row within an episode"
            )
    return seed


def _check_time(t: np.ndarray, lo: int, dt: float, where: str) -> None:
    allowed = (
        f"allowed: time_s rising by the sidecar's sample_time_s={dt:g} s per row within an "
        f"episode (±{TIME_TOLERANCE_S:g} s)"
    )
    down = np.flatnonzero(np.diff(t) <= 0)
    if down.size:
        j = int(down[0]) + 1
        raise ValueError(
            f"{where}: column 'time_s', data row {lo + j}: time_s goes from {t[j - 1]:g} s to "
            f"{t[j]:g} s, not increasing; {allowed}"
        )
    drift = np.abs(t - t[0] - np.arange(len(t)) * dt)
    off = np.flatnonzero(drift > TIME_TOLERANCE_S + 1e-9 * np.abs(t))
    if off.size:
        j = int(off[0])
        step = float(t[j] - t[j - 1])
        m = round(step / dt)
        # after rows that kept time, a jump by whole periods is a gap; at the first step it
        # is as likely a wrong sample time, so it is reported as a step
        if j >= 2 and m >= 2 and abs(step - m * dt) <= TIME_TOLERANCE_S:
            what = (
                f"time_s jumps from {t[j - 1]:g} s to {t[j]:g} s: about {m - 1} missing "
                f"sample{'s' if m > 2 else ''}"
            )
        else:
            typical = float(np.median(np.diff(t))) if len(t) > 1 else step
            what = (
                f"time_s steps by {step:g} s (from {t[j - 1]:g} s to {t[j]:g} s; the episode's "
                f"median step is {typical:g} s)"
            )
        raise ValueError(f"{where}: column 'time_s', data row {lo + j}: {what}; {allowed}")
