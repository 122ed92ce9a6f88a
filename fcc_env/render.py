"""The env's ``rgb_array`` frames, drawn fast enough for ``render_fps``.

A fresh matplotlib figure per frame (:func:`fcc_env.plotting.trend_image`) costs a few hundred
milliseconds: eight to eleven axes lay out, tick and draw their text anew. :class:`TrendRenderer`
keeps one figure per env and redraws only what a new sample changes. The axes (spines, ticks,
labels, units, the onset marker, the legend) are drawn once into a cached background; a frame
restores it and draws the data lines (measurements, valve command, set points, reward) and the
title over it (matplotlib's blitting). The background is redrawn only when a limit moves:

* the time axis pages: it spans :data:`WINDOW_SAMPLES` + :data:`PAGE_SAMPLES` samples and moves
  by :data:`PAGE_SAMPLES` once the newest sample reaches its right edge, so the last
  :data:`WINDOW_SAMPLES` samples are always in view;
* a value axis changes only when its data leave it or fill less than :data:`MIN_FILL` of it,
  and is then set with :data:`Y_MARGIN` of the data range above and below.

The panels, their labels and units, the onset marker and the legend come from
:func:`fcc_env.plotting.trend_figure` itself (its layout, :func:`fcc_env.plotting.trend_layout`:
Table 1 for ``FCC-v0``; the two loops with their set points and the valve command on the
closed-loop ids; the reward and its cumulative sum on ``FCC-control-v0``), rebuilt when the
onset enters or leaves the window.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from fcc_env.plotting import TABLE1_CHANNELS, trend_title

#: Samples of history a frame shows (the newest last).
WINDOW_SAMPLES = 500
#: How far the time axis moves at a time (samples); the axis spans the window plus one page.
PAGE_SAMPLES = 50
#: Share of a value axis's data range added above and below when the axis is set.
Y_MARGIN = 0.25
#: A value axis is reset when its data fill less than this share of it.
MIN_FILL = 0.3

__all__ = [
    "MIN_FILL",
    "PAGE_SAMPLES",
    "WINDOW_SAMPLES",
    "Y_MARGIN",
    "TrendRenderer",
]


def _time_limits(k_now: int) -> tuple[int, int]:
    # [left, right] in samples: the right edge is the next page boundary at or after k_now + 1
    right = math.ceil((k_now + 1) / PAGE_SAMPLES) * PAGE_SAMPLES
    return max(right - WINDOW_SAMPLES - PAGE_SAMPLES, 0), right


def _value_limits(lo: float, hi: float) -> tuple[float, float]:
    span = hi - lo
    if span <= 1e-9 * max(abs(lo), abs(hi), 1.0):  # flat data: ±5 % around the value
        half = 0.05 * abs(lo) or 1.0
        return lo - half, hi + half
    return lo - Y_MARGIN * span, hi + Y_MARGIN * span


class TrendRenderer:
    """One env's trend frames: a persistent figure whose lines and title are updated per frame.

    Build it lazily (matplotlib is imported on the first :meth:`frame`); :meth:`close` drops the
    figure.
    """

    def __init__(self) -> None:
        self.close()

    def close(self) -> None:
        """Drop the figure and the cached background (the next frame builds them anew)."""
        self._fig: Any = None
        self._axes: list[Any] = []
        self._lines: list[tuple[Any, int]] = []
        self._panels: list[list[int]] = []
        self._key: Any = None
        self._title: Any = None
        self._background: Any = None
        self._xlim: tuple[int, int] | None = None
        self._ylim: list[tuple[float, float]] = []

    @property
    def figure(self) -> Any:
        """The matplotlib Figure of the last frame (``None`` before the first or after close)."""
        return self._fig

    def frame(
        self,
        y: np.ndarray,
        k_now: int,
        sample_time_s: float,
        *,
        channels: Mapping[str, str] | None = None,
        env_id: str | None = None,
        scenario: str | None = None,
        fault_onset: int | None = None,
    ) -> np.ndarray:
        """RGB frame (H, W, 3) uint8 of the data ``y`` (n, c), which end at sample ``k_now``;
        arguments as :func:`fcc_env.plotting.trend_figure` (``channels`` names the columns of
        ``y`` and their units; the figure's size, hence the frame's shape, follows from them)."""
        channels = TABLE1_CHANNELS if channels is None else channels
        y = y[-WINDOW_SAMPLES:]
        n = y.shape[0]
        # The onset marker is drawn while the onset is inside the shown samples (as trend_figure).
        in_window = fault_onset is not None and k_now - n + 1 <= fault_onset <= k_now
        onset_shown = fault_onset if in_window else None
        key = (tuple(channels.items()), onset_shown)
        if self._fig is None or key != self._key:
            self._build(y, k_now, sample_time_s, channels, env_id, scenario, onset_shown)
            self._key = key
        hours = sample_time_s / 3600.0
        t_h = np.arange(k_now - n + 1, k_now + 1) * hours
        for line, col in self._lines:
            line.set_data(t_h, y[:, col])
        title = trend_title(k_now, sample_time_s, scenario, fault_onset, env_id)
        self._title.set_text(title)
        if self._limits_moved(y, k_now, hours) or self._background is None:
            self._redraw_background()
        canvas = self._fig.canvas
        canvas.restore_region(self._background)
        for ax in self._axes:
            for line in ax.get_lines():  # the data, then the onset marker over them
                ax.draw_artist(line)
        self._fig.draw_artist(self._title)
        return np.asarray(canvas.buffer_rgba())[..., :3].copy()

    # ---- internals ---------------------------------------------------------------------------
    def _build(
        self,
        y: np.ndarray,
        k_now: int,
        sample_time_s: float,
        channels: Mapping[str, str],
        env_id: str | None,
        scenario: str | None,
        onset_shown: int | None,
    ) -> None:
        from matplotlib.text import Text

        from fcc_env.plotting import trend_figure  # the one definition of the panels

        self.close()
        fig = trend_figure(
            y,
            k_now,
            sample_time_s,
            channels=channels,
            env_id=env_id,
            scenario=scenario,
            fault_onset=onset_shown,
        )
        title = fig.get_suptitle()
        self._title = next(t for t in fig.findobj(Text) if t.get_text() == title)
        self._axes = list(fig.axes)
        # every data line names its channel (gid); the columns of y are the channels in order
        column = {name: i for i, name in enumerate(channels)}
        self._lines = [
            (ln, column[ln.get_gid()])
            for ax in self._axes
            for ln in ax.get_lines()
            if ln.get_gid() is not None
        ]
        self._panels = [
            [column[ln.get_gid()] for ln in ax.get_lines() if ln.get_gid() is not None]
            for ax in self._axes
        ]
        # animated artists are left out of canvas.draw(): they are what a frame redraws (every
        # line of a panel, so the onset marker stays drawn over the data)
        for artist in (*(ln for ax in self._axes for ln in ax.get_lines()), self._title):
            artist.set_animated(True)
        self._fig = fig

    def _limits_moved(self, y: np.ndarray, k_now: int, hours: float) -> bool:
        moved = False
        xlim = _time_limits(k_now)
        if xlim != self._xlim:
            self._xlim = xlim
            self._axes[0].set_xlim(xlim[0] * hours, xlim[1] * hours)  # shared by all panels
            self._ylim = []  # a new page also re-fits the value axes
            moved = True
        if not self._ylim:
            self._ylim = [(math.nan, math.nan)] * len(self._axes)
        for i, (ax, cols) in enumerate(zip(self._axes, self._panels, strict=True)):
            lo, hi = float(y[:, cols].min()), float(y[:, cols].max())
            a, b = self._ylim[i]
            fits = a <= lo and hi <= b and hi - lo >= MIN_FILL * (b - a)
            if not fits and (new := _value_limits(lo, hi)) != (a, b):
                self._ylim[i] = new
                ax.set_ylim(*new)
                moved = True
        return moved

    def _redraw_background(self) -> None:
        canvas = self._fig.canvas
        canvas.draw()
        self._background = canvas.copy_from_bbox(self._fig.bbox)
