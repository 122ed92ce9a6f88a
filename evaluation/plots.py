"""Figures in the style of the paper's Fig. 3 / Fig. 4: a monitored signal with its band or limit.

Pure presentation: functions take an :class:`~diagnosers.base.Episode` and the
:class:`~diagnosers.base.Detection` a diagnoser produced on it and return a
:class:`matplotlib.figure.Figure` drawn on an Agg canvas. No pyplot (no global figure state, no
``show``), so it is safe in workers and tests; :func:`save_png` writes the file.

Each figure has one panel per monitored signal (at most ``max_signals``; with more, those that
leave their band most often are shown, since they explain the alarms) with the measured signal or
statistic, its lower/upper limit (a band for two-sided checks), the fault onset as a dashed
vertical line and alarmed samples shaded; a last panel shows the alarm sequence.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from diagnosers.base import Detection, Episode

__all__ = ["detection_figure", "save_png", "select_signals"]

_ONSET_STYLE = {"color": "tab:red", "linestyle": "--", "linewidth": 1.2}
_ALARM_COLOR = "tab:orange"


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


def detection_figure(
    episode: Episode,
    det: Detection,
    *,
    title: str | None = None,
    max_signals: int = 3,
    fault_onset: int | None = None,
) -> Figure:
    """Draw ``det`` over ``episode`` (see the module doc for the layout).

    Args:
        episode: the scored episode (its ``fault_onset`` marks the onset unless
            ``fault_onset`` is given).
        det: the diagnoser's detection on ``episode`` (same number of samples).
        title: figure title; default names the scenario and seed.
        max_signals: at most this many signal panels (``>= 1``).
        fault_onset: onset sample to mark, overriding ``episode.fault_onset``.
    """
    if max_signals < 1:
        raise ValueError(f"max_signals={max_signals!r} must be >= 1")
    n = episode.n_samples
    if det.alarm.shape != (n,):
        raise ValueError(
            f"detection has {det.alarm.shape[0]} samples but the episode has {n}; "
            "pass the episode the detection was computed on"
        )
    onset = episode.fault_onset if fault_onset is None else fault_onset
    idx = select_signals(det, max_signals)
    t = np.arange(n)
    fig = Figure(figsize=(9.0, 2.2 * len(idx) + 1.4), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(
        len(idx) + 1, 1, sharex=True, gridspec_kw={"height_ratios": [3] * len(idx) + [1]}
    )
    for ax, j in zip(axes[:-1], idx, strict=True):
        s, lo, hi = det.signal[:, j], det.lower[:, j], det.upper[:, j]
        ax.plot(t, s, color="tab:blue", linewidth=0.7, label="signal")
        lo_ok, hi_ok = np.isfinite(lo), np.isfinite(hi)
        if np.array_equal(lo_ok, hi_ok) and lo_ok.mean() > 0.5:
            # a two-sided band (absent where the diagnoser sets no limit, e.g. its warm-up)
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
                ax.plot(t, np.where(lo_ok, lo, np.nan), color="k", linewidth=1.0)
        # A one-sided, positive statistic (T², SPE) spans decades after a fault; exact zeros (a
        # diagnoser's silent warm-up) are simply not drawn on the log axis.
        if not lo_ok.any() and np.all(s >= 0) and np.mean(s > 0) > 0.5:
            ax.set_yscale("log")
        ax.fill_between(
            t,
            0,
            1,
            where=det.alarm,
            transform=ax.get_xaxis_transform(),
            color=_ALARM_COLOR,
            alpha=0.15,
            linewidth=0,
        )
        if onset is not None:
            ax.axvline(onset, **_ONSET_STYLE, label="fault onset")
        ax.set_ylabel(det.signal_names[j])
        ax.legend(loc="upper left", fontsize="small", ncol=3)
    ax_a = axes[-1]
    ax_a.step(t, det.alarm.astype(float), where="post", color=_ALARM_COLOR, linewidth=0.8)
    if onset is not None:
        ax_a.axvline(onset, **_ONSET_STYLE)
    if det.diagnosis is not None:  # an isolating diagnoser: its diagnosis along the time axis
        labels = [x for x in dict.fromkeys(det.diagnosis.tolist()) if x]
        for i, lab in enumerate(labels):
            ax_a.fill_between(
                t,
                0,
                1,
                where=det.diagnosis == lab,
                step="post",
                color=f"C{i}",
                alpha=0.6,
                linewidth=0,
                label=f"diagnosis: {lab}",
            )
        if labels:
            ax_a.legend(loc="upper left", fontsize="small", ncol=min(len(labels), 5))
    ax_a.set_ylim(-0.1, 1.1)
    ax_a.set_yticks([0, 1], ["ok", "alarm"])
    ax_a.set_xlabel(f"sample (Ts = {episode.sample_time_s:g} s)")
    ax_a.set_xlim(0, max(n - 1, 1))
    if title is None:
        title = f"{episode.scenario}, seed {episode.seed}"
    fig.suptitle(title)
    return fig


def save_png(fig: Figure, path: str | os.PathLike, dpi: int = 100) -> Path:
    """Write ``fig`` as PNG to ``path`` (parent directories are created)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi, format="png")  # the Agg canvas attached in detection_figure
    return path
