"""Figures in the style of the paper's Fig. 3 / Fig. 4: a monitored signal with its band or limit.

Pure presentation: functions take an :class:`~diagnosers.episode.record.Episode` and the
:class:`~diagnosers.detection.Detection` a diagnoser produced on it and return a
:class:`matplotlib.figure.Figure` drawn on an Agg canvas. No pyplot (no global figure state, no
``show``), so it is safe in workers and tests; :func:`save_png` writes the file.

Each figure has one panel per monitored signal (at most ``max_signals``; with more, those that
leave their band most often are shown, since they explain the alarms, and the subtitle says so)
with the measured signal or statistic and its unit (the episode's own, :attr:`Episode.units`),
its lower/upper limit (a band for two-sided checks), the fault onset as a dashed vertical line
("fault onset (assumed)" when the data do not state it) and the detector's alarms shaded. A last strip
shows the detector's decision; when the panels show another view of the same models (a
:meth:`~diagnosers.contract.DiagnoserContract.band_view`), the view's own exits are a second,
named row of the strip, never mistaken for alarms. One legend for the whole figure sits below
the panels.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from diagnosers.detection import Detection
from diagnosers.episode.record import Episode
from fcc_env.params import MEASUREMENTS

__all__ = [
    "ASSUMED_ONSET_LABEL",
    "ONSET_LABEL",
    "axis_label",
    "confusion_figure",
    "detection_figure",
    "save_png",
    "select_signals",
]

_ONSET_STYLE = {"color": "tab:red", "linestyle": "--", "linewidth": 1.2}
_ALARM_COLOR = "tab:orange"
_EXIT_COLOR = "tab:purple"
#: Strip labels: the detector's decision and, for a band view, the view's own exits.
ALARM_LABEL = "detector alarm"
EXIT_LABEL = "band exit (an output outside its band; not an alarm)"
#: The onset line's label, and its label for an onset the data do not state.
ONSET_LABEL = "fault onset"
ASSUMED_ONSET_LABEL = "fault onset (assumed)"
#: How units written in ASCII by data sets (e.g. the Santander columns.csv) are shown.
_UNIT_SYMBOLS = {"degF": "°F", "degC": "°C", "degR": "°R"}

_UNITS = {m.name: m.unit for m in MEASUREMENTS}
_HAS_UNIT = re.compile(r"\s\[[^\]]*\]$")  # "T_rx [°C]": a name that already carries its unit
_EWMA_OF = re.compile(r"^ewma\[(.+)\]$")


def axis_label(name: str, units: Mapping[str, str] | None = None) -> str:
    """The y-axis label of signal ``name``, with its unit in brackets.

    ``units`` maps channels to the units their data state (``""``: unknown), e.g. an episode's
    :attr:`~diagnosers.episode.record.Episode.channel_units`. A channel in ``units`` takes that unit,
    or no bracket at all when it is unknown, never a guessed one; this also replaces a unit a
    diagnoser wrote into the name (``"Tr [°C]"`` of a band view on data in °F). Only when
    ``units`` is ``None`` (nothing known, e.g. figure arrays stored before episodes carried
    units) do FCC-v0 channel names take the units of :data:`fcc_env.params.MEASUREMENTS`, and
    a name that ends in ``" [unit]"`` is kept. Test statistics (``T2``, ``SPE``, EWMA of
    normalised residuals) are dimensionless, ``[-]``; any other name is shown as it is.
    """
    carried = _HAS_UNIT.search(name)
    base = name[: carried.start()] if carried else name
    if units is not None and base in units:  # the data's own word on this channel
        unit = _UNIT_SYMBOLS.get(units[base].strip(), units[base].strip())
        return f"{base} [{unit}]" if unit else base
    if carried:
        return name
    if units is None and name in _UNITS:
        return f"{name} [{_UNITS[name]}]"
    if name == "T2":
        return "T² [-]"
    if name == "SPE":
        return "SPE [-]"
    if name == "T2[ewma]":
        return "T² of EWMA residuals [-]"
    m = _EWMA_OF.match(name)
    if m:
        return f"EWMA of {m.group(1)} residual [-]"
    return name


def _panel_units(
    episode: Episode, det: Detection, j: int, units: Mapping[str, str] | None
) -> Mapping[str, str] | None:
    """The units that label panel ``j``: ``units`` (the caller's word) and, when the panel
    draws a channel's own values, that channel's unit from the episode.

    The episode's unit goes by the data, not by the name alone, so a statistic that shares a
    channel's name (Hotelling's ``T2`` on data with a temperature ``T2``) is not given the
    channel's unit. ``None`` when nothing is known (then :func:`axis_label` falls back).
    """
    own = episode.channel_units
    if not own and not units:
        return None
    name = _HAS_UNIT.sub("", det.signal_names[j])
    out = {}
    if name in own and np.array_equal(det.signal[:, j], episode.channel(name), equal_nan=True):
        out[name] = own[name]
    return {**out, **(units or {})}


def select_signals(det: Detection, max_signals: int) -> list[int]:
    """Indices of the signals to draw: all if few, else those most often out of their limits.

    Ties keep the diagnoser's order (a stable sort), so the choice is deterministic.
    """
    k = det.signal.shape[1]
    if k <= max_signals:
        return list(range(k))
    out = np.count_nonzero((det.signal < det.lower) | (det.signal > det.upper), axis=0)
    order = np.argsort(-out, kind="stable")[:max_signals]
    return sorted(int(i) for i in order)


def _check_samples(what: str, det: Detection, n: int) -> None:
    if det.alarm.shape != (n,):
        raise ValueError(
            f"{what} has {det.alarm.shape[0]} samples but the episode has {n}; "
            "pass the episode the detection was computed on"
        )


def _shown_text(det: Detection, idx: list[int], kind: str) -> str:
    """Which signals the panels show and why (the figure's subtitle)."""
    k = det.signal.shape[1]
    if k == 1:
        return "the one monitored signal"
    if len(idx) == k:
        return f"all {k} monitored signals shown"
    names = ", ".join(det.signal_names[j] for j in idx)
    return f"shown: {names} ({len(idx)} of {k} monitored signals, those most often outside their {kind})"


def _raster(ax, t: np.ndarray, on: np.ndarray, row: int, color: str, label: str) -> None:
    """One on/off row of the strip: a step line at ``row`` rising by 0.8 where ``on``."""
    y = row + 0.8 * on.astype(float)
    ax.fill_between(t, row, y, step="post", color=color, alpha=0.5, linewidth=0)
    ax.step(t, y, where="post", color=color, linewidth=0.8, label=label)


def detection_figure(
    episode: Episode,
    det: Detection,
    *,
    title: str | None = None,
    max_signals: int = 3,
    fault_onset: int | None = None,
    decisions: Detection | None = None,
    units: Mapping[str, str] | None = None,
    onset_assumed: bool = False,
) -> Figure:
    """Draw ``det`` over ``episode`` (see the module doc for the layout).

    Args:
        episode: the scored episode (its ``fault_onset`` marks the onset unless
            ``fault_onset`` is given).
        det: what the panels show: the diagnoser's detection on ``episode``, or another view of
            it (a band view, then pass the detection as ``decisions``); same number of samples.
        title: figure title; default names the scenario and seed.
        max_signals: at most this many signal panels (``>= 1``).
        fault_onset: onset sample to mark, overriding ``episode.fault_onset``.
        decisions: the detector's own detection when ``det`` is another view of it: its
            ``alarm`` is shaded and is the strip's alarm row, while ``det.alarm`` (e.g. band
            exits) becomes a separate row named :data:`EXIT_LABEL`. ``None``: ``det`` is the
            detection.
        units: units by channel name, over the episode's own (:attr:`Episode.units`); e.g.
            the data source's units for an episode stored without them.
        onset_assumed: the onset is assumed, not stated by the data: its line is labelled
            :data:`ASSUMED_ONSET_LABEL`.
    """
    if max_signals < 1:
        raise ValueError(f"max_signals={max_signals!r} must be >= 1")
    n = episode.n_samples
    _check_samples("detection", det, n)
    if decisions is not None:
        _check_samples("decisions", decisions, n)
    alarm = det.alarm if decisions is None else decisions.alarm
    onset = episode.fault_onset if fault_onset is None else fault_onset
    idx = select_signals(det, max_signals)
    onset_label = ASSUMED_ONSET_LABEL if onset_assumed else ONSET_LABEL
    t = np.arange(n)
    fig = Figure(figsize=(9.0, 2.2 * len(idx) + 2.2), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(
        len(idx) + 1, 1, sharex=True, gridspec_kw={"height_ratios": [3] * len(idx) + [1]}
    )
    kind = "limits"
    for ax, j in zip(axes[:-1], idx, strict=True):
        s, lo, hi = det.signal[:, j], det.lower[:, j], det.upper[:, j]
        ax.plot(t, s, color="tab:blue", linewidth=0.7, label="signal")
        lo_ok, hi_ok = np.isfinite(lo), np.isfinite(hi)
        if np.array_equal(lo_ok, hi_ok) and lo_ok.mean() > 0.5:
            # a two-sided band (absent where the diagnoser sets no limit, e.g. its warm-up)
            # limits constant over the record are a limit pair, else a model's band
            if lo_ok.any() and (np.ptp(lo[lo_ok]) > 0 or np.ptp(hi[hi_ok]) > 0):
                kind = "bands"
            ax.fill_between(
                t,
                np.where(lo_ok, lo, 0.0),
                np.where(hi_ok, hi, 0.0),
                where=lo_ok,
                color="tab:green",
                alpha=0.25,
                linewidth=0,
                label="band",
            )
        else:
            if hi_ok.any():
                ax.plot(t, np.where(hi_ok, hi, np.nan), color="k", linewidth=1.0, label="limit")
            if lo_ok.any():
                ax.plot(t, np.where(lo_ok, lo, np.nan), color="k", linewidth=1.0, label="limit")
        # A one-sided, positive statistic (T², SPE) spans decades after a fault; exact zeros (a
        # diagnoser's silent warm-up) are simply not drawn on the log axis.
        if not lo_ok.any() and np.all(s >= 0) and np.mean(s > 0) > 0.5:
            ax.set_yscale("log")
        ax.fill_between(
            t,
            0,
            1,
            where=alarm,
            transform=ax.get_xaxis_transform(),
            color=_ALARM_COLOR,
            alpha=0.15,
            linewidth=0,
        )
        if onset is not None:
            ax.axvline(onset, **_ONSET_STYLE, label=onset_label)
        ax.set_ylabel(axis_label(det.signal_names[j], _panel_units(episode, det, j, units)))
    hours = 3600.0 / episode.sample_time_s
    top = axes[0].secondary_xaxis("top", functions=(lambda k: k / hours, lambda h: h * hours))
    top.set_xlabel("time [h]")
    ax_a = axes[-1]
    rows = [(alarm, _ALARM_COLOR, ALARM_LABEL)]
    if decisions is not None:
        rows.insert(0, (det.alarm, _EXIT_COLOR, EXIT_LABEL))
    for r, (on, color, label) in enumerate(rows):
        _raster(ax_a, t, on, r, color, label)
    if onset is not None:
        ax_a.axvline(onset, **_ONSET_STYLE)
    if det.diagnosis is not None:  # an isolating diagnoser: its diagnosis along the time axis
        labels = [x for x in dict.fromkeys(det.diagnosis.tolist()) if x]
        for i, lab in enumerate(labels):
            rows.append((det.diagnosis == lab, f"C{i}", f"diagnosis: {lab}"))
            _raster(ax_a, t, det.diagnosis == lab, len(rows) - 1, f"C{i}", f"diagnosis: {lab}")
    ax_a.set_ylim(-0.1, len(rows) - 0.1)
    ax_a.set_yticks(
        [r + 0.4 for r in range(len(rows))], [label.split(" (")[0] for *_, label in rows]
    )
    ax_a.set_ylabel("state [on/off]")
    ax_a.set_xlabel(f"sample [-] (Ts = {episode.sample_time_s:g} s)")
    ax_a.set_xlim(0, max(n - 1, 1))
    # One legend for the figure, outside the panels: it never covers data.
    handles, labels = [], []
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab not in labels and lab != ALARM_LABEL:
                handles.append(h)
                labels.append(lab)
    handles.append(Patch(color=_ALARM_COLOR, alpha=0.4))
    labels.append(f"{ALARM_LABEL} (shaded)")
    fig.legend(
        handles, labels, loc="outside lower center", ncol=min(len(labels), 3), fontsize="small"
    )
    if title is None:
        title = f"{episode.scenario}, seed {episode.seed}"
    fig.suptitle(f"{title}\n{_shown_text(det, idx, kind)}", fontsize="medium")
    return fig


def save_png(fig: Figure, path: str | os.PathLike, dpi: int = 100) -> Path:
    """Write ``fig`` as PNG to ``path`` (parent directories are created)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi, format="png")  # the Agg canvas attached in detection_figure
    return path


def confusion_figure(
    rows: list[str], cols: list[str], counts: np.ndarray, title: str, path: Path
) -> Path:
    """The confusion matrix as a labelled heat map (episodes per cell)."""
    fig = Figure(figsize=(1.2 + 0.9 * len(cols), 1.0 + 0.7 * len(rows)))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    m = np.asarray(counts)
    ax.imshow(m, cmap="Blues", vmin=0)
    ax.set_xticks(range(len(cols)), cols, rotation=30, ha="right")
    ax.set_yticks(range(len(rows)), rows)
    ax.set_xlabel("diagnosis (majority label of the alarmed post-onset samples)")
    ax.set_ylabel("true fault")
    for i in range(m.shape[0]):
        for j in range(m.shape[1]):
            ax.text(
                j,
                i,
                str(m[i, j]),
                ha="center",
                va="center",
                color="white" if m[i, j] > m.max() / 2 else "black",
            )
    ax.set_title(title + " [episodes]", fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    return path


def reliability_figure(
    curves: Mapping[str, tuple[np.ndarray, np.ndarray, np.ndarray]], title: str, path: Path
) -> Path:
    """Reliability diagram: per diagnoser (label -> :func:`~evaluation.metrics.probability_metrics.reliability_curve`'s
    mean prediction, observed frequency, count per bin), the observed frequency against the
    mean predicted probability, with the diagonal of perfect calibration; a lower panel shows
    how many predictions fall in each bin (log scale)."""
    fig = Figure(figsize=(5.2, 6.0))
    FigureCanvasAgg(fig)
    ax, axn = fig.subplots(2, 1, height_ratios=(3, 1), sharex=True)
    ax.plot([0, 1], [0, 1], color="0.6", linestyle=":", label="perfectly calibrated")
    for label, (mean_p, freq, count) in curves.items():
        keep = np.asarray(count) > 0
        (line,) = ax.plot(np.asarray(mean_p)[keep], np.asarray(freq)[keep], marker="o", label=label)
        edges = np.linspace(0, 1, len(count) + 1)
        axn.stairs(np.maximum(np.asarray(count), 0.5), edges, color=line.get_color())
    ax.set_ylabel("observed frequency of the hypothesis [–]")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title(title, fontsize=9)
    axn.set_yscale("log")
    axn.set_xlabel("predicted probability of a hypothesis (bin mean) [–]")
    axn.set_ylabel("predictions [samples × hypotheses]", fontsize=7)
    fig.tight_layout()
    return save_png(fig, path)
