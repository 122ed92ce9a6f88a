"""The episode readers refuse bad input clearly (issue 32): a campaign of bad rows, sidecars,
tables, arrays and frames, each refused with a message that names the bad value (and the file,
column and row where there is one) and the allowed form.

Each case is ``(id, build, patterns)``: ``build`` makes the bad input and calls the reader; every
regular expression of ``patterns`` must occur in the error message.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from diagnosers import Episode
from fcc_env.generate import write_dataset

N = 150  # samples per episode: more than the 100 that one case drops
DT = 10.0


@dataclass
class Table:
    """A dataset as text fields, to be damaged by a case and written back."""

    header: list[str]
    rows: list[list[str]]
    meta: dict[str, Any]
    sidecar_bytes: bytes | None = field(default=None)
    csv_bytes: bytes | None = field(default=None)

    def j(self, name: str) -> int:
        return self.header.index(name)

    def set(self, name: str, row: int, value: str) -> None:
        self.rows[row][self.j(name)] = value

    def write(self, folder: Path) -> Path:
        path = folder / "d.csv"
        text = "\n".join(",".join(r) for r in [self.header, *self.rows]) + "\n"
        path.write_bytes(self.csv_bytes if self.csv_bytes is not None else text.encode())
        side = self.sidecar_bytes or json.dumps(self.meta).encode()
        path.with_suffix(".json").write_bytes(side)
        return path


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Table:
    path = write_dataset(
        tmp_path_factory.mktemp("base") / "d.csv", scenario="f1", seeds=[0, 1], n_samples=N,
        fault_time=120,
    )  # fmt: skip
    header, *rows = path.read_text().splitlines()
    meta = json.loads(path.with_suffix(".json").read_text())
    return Table(header.split(","), [r.split(",") for r in rows], meta)


def _fresh(base: Table) -> Table:
    return Table(list(base.header), [list(r) for r in base.rows], json.loads(json.dumps(base.meta)))


# ---- damage to the CSV or its sidecar ------------------------------------------------------------
def _times(step: float) -> Callable[[Table], None]:
    def f(t: Table) -> None:
        for i, r in enumerate(t.rows):
            r[t.j("time_s")] = f"{(i % N) * step:.1f}"

    return f


def _reverse_first(t: Table) -> None:
    t.rows[:N] = t.rows[:N][::-1]


def _swap(t: Table) -> None:
    t.rows[10], t.rows[11] = t.rows[11], t.rows[10]


def _repeat_row(t: Table) -> None:
    t.rows.insert(21, list(t.rows[20]))


def _drop(lo: int, hi: int) -> Callable[[Table], None]:
    def f(t: Table) -> None:
        del t.rows[lo:hi]

    return f


def _splice(t: Table) -> None:  # episode 1 relabelled 0: one 300-sample "episode" of two seeds
    for r in t.rows[N:]:
        r[t.j("episode")] = "0"


def _interleave(t: Table) -> None:  # ten rows of episode 1 moved into the middle of episode 0
    moved = t.rows[N : N + 10]
    del t.rows[N : N + 10]
    t.rows[50:50] = moved


def _cell(name: str, row: int, value: str) -> Callable[[Table], None]:
    return lambda t: t.set(name, row, value)


def _meta(key: str, value: Any) -> Callable[[Table], None]:
    def f(t: Table) -> None:
        if value is _DELETE:
            del t.meta[key]
        else:
            t.meta[key] = value

    return f


_DELETE = object()


def _measured(value: Any) -> Callable[[Table], None]:
    def f(t: Table) -> None:
        t.meta["roles"]["measured"] = value

    return f


def _header(old: str, new: str) -> Callable[[Table], None]:
    def f(t: Table) -> None:
        t.header[t.j(old)] = new

    return f


def _raw_csv(edit: Callable[[bytes], bytes]) -> Callable[[Table], None]:
    def f(t: Table) -> None:
        text = "\n".join(",".join(r) for r in [t.header, *t.rows]) + "\n"
        t.csv_bytes = edit(text.encode())

    return f


def _bad_byte_in_line(line: int) -> Callable[[bytes], bytes]:
    def f(b: bytes) -> bytes:
        lines = b.split(b"\n")
        lines[line - 1] = lines[line - 1].replace(b",", b",\xff", 1)
        return b"\n".join(lines)

    return f


def _bad_sidecar_bytes(t: Table) -> None:
    t.sidecar_bytes = json.dumps(t.meta).replace('"f1"', '"f\xe91"').encode("latin-1")


def _short_row(t: Table) -> None:
    t.rows[4] = t.rows[4][:5]


def _header_only(t: Table) -> None:
    t.rows = []


F = r"d\.csv"
CSV_CASES: list[tuple[str, Callable[[Table], None], list[str]]] = [
    # time_s
    (
        "time-step-5s-under-10s",
        _times(5.0),
        [F, "'time_s'", r"data row 1\b", "steps by 5 s", "sample_time_s=10 s"],
    ),
    ("time-step-20s-under-10s", _times(20.0), [F, "'time_s'", r"data row 1\b", "steps by 20 s"]),
    ("time-reversed-rows", _reverse_first, [F, "'time_s'", r"data row 1\b", "not increasing"]),
    ("time-two-rows-swapped", _swap, [F, "'time_s'", r"data row 11\b", "not increasing"]),
    ("time-repeated-row", _repeat_row, [F, "'time_s'", r"data row 21\b", "not increasing"]),
    ("time-100-missing", _drop(20, 120), [F, "'time_s'", r"data row 20\b", "100 missing samples"]),
    ("time-1-missing", _drop(50, 51), [F, "'time_s'", r"data row 50\b", "1 missing sample"]),
    ("time-text", _cell("time_s", 3, "ten"), [F, "'time_s'", r"data row 3\b", "'ten'"]),
    (
        "sidecar-dt-5-data-10",
        _meta("sample_time_s", 5.0),
        [F, "'time_s'", "steps by 10 s", "sample_time_s=5 s"],
    ),
    # the episode and seed columns
    ("two-seeds-one-episode", _splice, [F, "episode 0", r"seeds \[0, 1\]", r"data row 150\b"]),
    (
        "episode-quarter",
        _cell("episode", 7, "0.25"),
        [F, "'episode'", r"data row 7\b", "0.25", "whole number"],
    ),
    ("episode-nan", _cell("episode", 9, "nan"), [F, "'episode'", r"data row 9\b", "nan"]),
    ("episode-interleaved", _interleave, [F, "episode 0", r"data row 60\b", "consecutive"]),
    ("seed-half", _cell("seed", 4, "0.5"), [F, "'seed'", r"data row 4\b", "0.5", "whole number"]),
    ("k-skips", _cell("k", 30, "31"), [F, "'k'", r"data row 30\b", "31"]),
    # sidecar: per-episode lists
    (
        "terminated-negative",
        _meta("terminated_at", [-5, None]),
        [r"terminated_at\[0\]=-5", r"integer in \[1, 150\]"],
    ),
    ("terminated-fraction", _meta("terminated_at", [60.5, None]), [r"terminated_at\[0\]=60\.5"]),
    ("terminated-bool", _meta("terminated_at", [True, None]), [r"terminated_at\[0\]=True"]),
    (
        "terminated-beyond",
        _meta("terminated_at", [151, None]),
        [r"terminated_at\[0\]=151", r"\[1, 150\]"],
    ),
    ("terminated-zero", _meta("terminated_at", [0, None]), [r"terminated_at\[0\]=0\b"]),
    ("terminated-string", _meta("terminated_at", "60"), [r"terminated_at='60'", "list"]),
    ("terminated-short", _meta("terminated_at", [60]), [r"terminated_at=\[60\]", "2 episodes"]),
    (
        "onset-fraction",
        _meta("fault_onsets", [150.7, 120]),
        [r"fault_onsets\[0\]=150\.7", "integer"],
    ),
    ("onset-bool", _meta("fault_onsets", [True, True]), [r"fault_onsets\[0\]=True", "integer"]),
    ("onset-negative", _meta("fault_onsets", [-3, 120]), [r"fault_onsets\[0\]=-3"]),
    ("onset-string", _meta("fault_onsets", "120"), [r"fault_onsets='120'", "list"]),
    ("seeds-disagree", _meta("seeds", [5, 6]), [r"seeds\[0\]=5", "'seed' column", r"\b0\b"]),
    ("seeds-string", _meta("seeds", "01"), [r"seeds='01'", "list"]),
    ("seeds-short", _meta("seeds", [0]), [r"seeds=\[0\]", "2 episodes"]),
    ("seeds-fraction", _meta("seeds", [0, 1.5]), [r"seeds\[1\]=1\.5"]),
    ("scenarios-string", _meta("scenarios", "f1"), [r"scenarios='f1'", "list"]),
    ("scenarios-numbers", _meta("scenarios", [1, 2]), [r"scenarios\[0\]=1", "text"]),
    ("scenario-number", _meta("scenario", 3), [r"scenario=3", "text"]),
    ("n-samples-disagree", _meta("n_samples", 200), [F, "episode 0", "150 rows", "n_samples=200"]),
    # sidecar: sample time and roles
    ("dt-text", _meta("sample_time_s", "ten"), [r"sample_time_s='ten'", r"\(0, inf\) s"]),
    ("dt-negative", _meta("sample_time_s", -10), [r"sample_time_s=-10", r"\(0, inf\) s"]),
    ("dt-zero", _meta("sample_time_s", 0), [r"sample_time_s=0\b"]),
    ("dt-bool", _meta("sample_time_s", True), [r"sample_time_s=True"]),
    ("dt-nan", _meta("sample_time_s", float("nan")), [r"sample_time_s=nan"]),
    ("dt-missing", _meta("sample_time_s", _DELETE), ["no sample_time_s"]),
    ("measured-string", _measured("T_rx"), [r"roles\.measured='T_rx'", "list"]),
    (
        "measured-duplicate",
        _measured(["T_rx", "T_rx"]),
        [r"roles\.measured=", "'T_rx'", "more than once"],
    ),
    ("measured-empty", _measured([]), [r"roles\.measured=\[\]", "non-empty"]),
    ("measured-numbers", _measured([1, 2]), [r"roles\.measured=\[1, 2\]"]),
    ("roles-string", _meta("roles", "measured"), [r"roles='measured'", "mapping"]),
    # values
    ("channel-text", _cell("T_rx", 3, "ten"), [F, "'T_rx'", r"data row 3\b", r"line 5\b", "'ten'"]),
    ("channel-empty-field", _cell("T_rg1", 6, ""), [F, "'T_rg1'", r"data row 6\b", "''"]),
    ("channel-nan", _cell("T_rx", 5, "nan"), [F, "'T_rx'", r"data row 5\b", "nan", "finite"]),
    ("channel-inf", _cell("T_dg", 8, "-inf"), [F, "'T_dg'", r"data row 8\b", "-inf", "finite"]),
    ("channel-complex", _cell("T_rx", 2, "1+2j"), [F, "'T_rx'", r"data row 2\b", r"'1\+2j'"]),
    ("channel-bool-text", _cell("T_rx", 2, "True"), [F, "'T_rx'", r"data row 2\b", "'True'"]),
    ("clean-nan", _cell("clean_T_rx", 4, "nan"), [F, "'clean_T_rx'", r"data row 4\b", "nan"]),
    ("channel-duplicate-column", _header("fault_active", "T_rx"), [F, "'T_rx'", "more than once"]),
    ("short-row", _short_row, [F, r"line 6\b", "fields"]),
    ("not-utf8-data", _raw_csv(_bad_byte_in_line(7)), [F, r"line 7\b", "UTF-8"]),
    ("not-utf8-header", _raw_csv(_bad_byte_in_line(1)), [F, r"line 1\b", "UTF-8"]),
    ("not-utf8-sidecar", _bad_sidecar_bytes, [r"d\.json", "UTF-8"]),
    ("empty-episode", _header_only, [F, "no data rows"]),
]


@pytest.mark.parametrize(("build", "patterns"), [c[1:] for c in CSV_CASES],
                         ids=[c[0] for c in CSV_CASES])  # fmt: skip
def test_bad_dataset_is_refused_clearly(base, tmp_path, build, patterns) -> None:
    t = _fresh(base)
    build(t)
    path = t.write(tmp_path)
    _assert_refused(lambda: Episode.from_dataset(path), ValueError, patterns)


# ---- Parquet tables: types a CSV cannot carry ------------------------------------------------------
def _parquet_cases() -> list[tuple[str, Callable[[int], Any], list[str]]]:
    P = r"d\.parquet"
    return [
        ("bool", lambda n: np.arange(n) % 2 == 0, [P, "'T_rx'", "bool"]),
        ("timestamp", lambda n: np.arange(n).astype("datetime64[s]"), [P, "'T_rx'", "timestamp"]),
        ("duration", lambda n: np.arange(n).astype("timedelta64[s]"), [P, "'T_rx'", "duration"]),
        ("string", lambda n: np.array(["ten"] * n), [P, "'T_rx'", "string"]),
        ("null", lambda n: [None if i == 3 else 1.0 for i in range(n)],
         [P, "'T_rx'", r"data row 3\b", "nan"]),
    ]  # fmt: skip


@pytest.mark.parametrize(("column", "patterns"), [c[1:] for c in _parquet_cases()],
                         ids=[c[0] for c in _parquet_cases()])  # fmt: skip
def test_bad_parquet_column_is_refused_clearly(base, tmp_path, column, patterns) -> None:
    pa = pytest.importorskip("pyarrow")
    pq = pytest.importorskip("pyarrow.parquet")
    data = {h: np.array([float(r[i]) for r in base.rows]) for i, h in enumerate(base.header)}
    data["T_rx"] = column(len(base.rows))
    path = tmp_path / "d.parquet"
    pq.write_table(pa.table(data), path)
    path.with_suffix(".json").write_text(json.dumps(base.meta))
    _assert_refused(lambda: Episode.from_dataset(path), ValueError, patterns)


# ---- the constructor ---------------------------------------------------------------------------
def _ep(y: Any = None, channels: Any = ("a", "b"), **kw: Any) -> Callable[[], Any]:
    y = np.ones((200, 2)) if y is None else y
    kw.setdefault("sample_time_s", DT)
    return lambda: Episode(y, channels, **kw)


def _nan_at(r: int, c: int) -> np.ndarray:
    y = np.ones((5, 2))
    y[r, c] = np.nan
    return y


CONSTRUCTOR_CASES: list[tuple[str, Callable[[], Any], list[str]]] = [
    ("bool", _ep(np.ones((3, 2), bool)), ["y", "bool", "real numbers"]),
    (
        "complex",
        _ep(np.array([[1.0, 2.0], [3.0, 4 + 5j]])),
        ["row 1", "channel 'b'", r"4\+5j", "complex"],
    ),
    ("datetime", _ep(np.arange(4).astype("datetime64[s]").reshape(2, 2)), ["datetime64"]),
    ("text", _ep([["1.0", "2"], ["3", "ten"]]), ["row 1", "channel 'b'", "'ten'"]),
    ("none", _ep(np.array([[1.0, None]], dtype=object)), ["row 0", "channel 'b'", "None"]),
    ("ragged", _ep([[1.0, 2.0], [3.0]]), ["ragged", "row 1"]),
    ("empty", _ep(np.zeros((0, 2))), ["no samples"]),
    ("nan", _ep(_nan_at(2, 1)), ["row 2", "channel 'b'", "nan", "finite"]),
    ("inf", _ep(np.full((3, 2), -np.inf)), ["row 0", "channel 'a'", "-inf"]),
    ("duplicate-channels", _ep(channels=("a", "a")), ["'a'", "more than once"]),
    ("no-channels", _ep(np.zeros((3, 0)), ()), [r"channels=\(\)", "non-empty"]),
    ("dt-text", _ep(sample_time_s="10"), [r"sample_time_s='10'", r"\(0, inf\) s"]),
    ("dt-bool", _ep(sample_time_s=True), [r"sample_time_s=True"]),
    ("dt-nan", _ep(sample_time_s=float("nan")), [r"sample_time_s=nan"]),
    ("onset-fraction", _ep(fault_onset=150.7), [r"fault_onset=150\.7", "integer"]),
    ("onset-bool", _ep(fault_onset=True), [r"fault_onset=True", "integer"]),
    ("onset-text", _ep(fault_onset="3"), [r"fault_onset='3'"]),
    ("onset-beyond", _ep(fault_onset=200), [r"fault_onset=200", r"\[0, 199\]"]),
    ("seed-fraction", _ep(seed=0.5), [r"seed=0\.5", "integer"]),
    ("seed-text", _ep(seed="7"), [r"seed='7'"]),
    ("seed-bool", _ep(seed=True), [r"seed=True"]),
    ("scenario-number", _ep(scenario=3), [r"scenario=3", "text"]),
    ("clean-shape", _ep(y_clean=np.ones((199, 2))), ["y_clean", r"\(199, 2\)", r"\(200, 2\)"]),
    ("clean-complex", _ep(y_clean=np.ones((200, 2)) * 1j), ["y_clean", "complex"]),
]


@pytest.mark.parametrize(("call", "patterns"), [c[1:] for c in CONSTRUCTOR_CASES],
                         ids=[c[0] for c in CONSTRUCTOR_CASES])  # fmt: skip
def test_bad_episode_is_refused_clearly(call, patterns) -> None:
    _assert_refused(call, ValueError, patterns)


# ---- from_frame --------------------------------------------------------------------------------
def _frame_cases() -> list[tuple[str, Callable[[Any], Any], list[str]]]:
    def frame(pd: Any, a: Any, **kw: Any) -> Any:
        b = np.arange(len(a), dtype=float)
        return pd.DataFrame({"a": a, "b": b}, **kw)

    def call(make: Callable[[Any], Any], **kw: Any) -> Callable[[Any], Any]:
        kw.setdefault("sample_time_s", DT)
        return lambda pd: Episode.from_frame(make(pd), **kw)

    ones = lambda pd: frame(pd, np.ones(200))  # noqa: E731
    return [
        ("bool", call(lambda pd: frame(pd, [True, False, True])), ["'a'", "bool"]),
        ("nullable-bool", call(lambda pd: frame(pd, pd.array([True, False], "boolean"))),
         ["'a'", "bool"]),
        ("datetime", call(lambda pd: frame(pd, pd.date_range("2024-01-01", periods=3))),
         ["'a'", "datetime"]),
        ("timedelta", call(lambda pd: frame(pd, pd.to_timedelta([1, 2], "s"))),
         ["'a'", "timedelta"]),
        ("complex", call(lambda pd: frame(pd, [1.0, 2 + 3j])), ["'a'", "row 1", r"2\+3j",
                                                                "complex"]),
        ("text", call(lambda pd: frame(pd, ["1", "2", "ten"])), ["'a'", "row 2", "'ten'",
                                                                 "must hold numbers"]),
        ("none", call(lambda pd: frame(pd, [1.0, None, "x"])), ["'a'", "row 1", "None"]),
        ("nan", call(lambda pd: frame(pd, [1.0, np.nan, 2.0])), ["'a'", "row 1", "nan",
                                                                 "finite"]),
        ("empty", call(lambda pd: frame(pd, np.zeros(0))), ["no samples"]),
        ("channels-string", call(ones, channels="ab"), [r"channels='ab'", "not one string"]),
        ("channels-duplicate", call(ones, channels=["a", "a"]), ["'a'", "more than once"]),
        ("columns-duplicate",
         call(lambda pd: pd.DataFrame(np.ones((3, 2)), columns=["a", "a"])),
         ["'a'", "more than once"]),
        ("dt-text", call(ones, sample_time_s="ten"), [r"sample_time_s='ten'"]),
        ("onset-fraction", call(ones, fault_onset=150.7), [r"fault_onset=150\.7"]),
        ("seed-fraction", call(ones, seed=2.5), [r"seed=2\.5"]),
    ]  # fmt: skip


@pytest.mark.parametrize(("call", "patterns"), [c[1:] for c in _frame_cases()],
                         ids=[c[0] for c in _frame_cases()])  # fmt: skip
def test_bad_frame_is_refused_clearly(call, patterns) -> None:
    pd = pytest.importorskip("pandas")
    _assert_refused(lambda: call(pd), ValueError, patterns)


# ---- valid input still reads, identically ------------------------------------------------------
def test_the_written_dataset_reads_as_before(base, tmp_path) -> None:
    path = _fresh(base).write(tmp_path)
    eps = Episode.from_dataset(path)
    data = np.array([[float(v) for v in r] for r in base.rows])
    ch = [base.j(c) for c in base.meta["roles"]["measured"]]
    for b, ep in enumerate(eps):
        assert (ep.seed, ep.scenario, ep.fault_onset, ep.n_samples) == (b, "f1", 120, N)
        np.testing.assert_array_equal(ep.y, data[b * N : (b + 1) * N, ch])
        assert ep.y.dtype == np.float64 and ep.sample_time_s == DT


def test_numeric_strings_and_objects_still_read() -> None:
    ep = Episode([["1.5", "2"], ["3", "4e1"]], ("a", "b"), 10)
    np.testing.assert_array_equal(ep.y, [[1.5, 2.0], [3.0, 40.0]])
    ep = Episode(np.array([[1, 2.5]], dtype=object), ("a", "b"), 10, fault_onset=np.int64(0))
    assert ep.y.dtype == np.float64 and ep.fault_onset == 0
    y = np.ones((4, 2))
    assert Episode(y, ("a", "b"), 10.0).y is y  # a float64 array is not copied


def _assert_refused(call: Callable[[], Any], exc: type[Exception], patterns: list[str]) -> None:
    with pytest.raises(exc) as info:
        call()
    text = str(info.value)
    missing = [p for p in patterns if not re.search(p, text)]
    assert not missing, f"message {text!r} lacks {missing}"
