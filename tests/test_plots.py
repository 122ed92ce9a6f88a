"""Figures (evaluation.plots): layout, scales and input checks."""

from __future__ import annotations

import numpy as np
import pytest

from diagnosers.base import Detection, Episode
from evaluation.plots import detection_figure, save_png, select_signals


def _episode(n: int = 300) -> Episode:
    return Episode(np.zeros((n, 2)), ("a", "b"), 10.0, fault_onset=n // 2, scenario="f1", seed=3)


def _detection(signal: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> Detection:
    alarm = np.any((signal < lower) | (signal > upper), axis=1)
    return Detection(
        alarm, signal, lower, upper, np.zeros_like(signal), ("s1", "s2")[: signal.shape[1]]
    )


def test_band_figure_layout_and_png(tmp_path) -> None:
    n = 300
    rng = np.random.default_rng(0)
    sig = rng.normal(size=(n, 2))
    sig[220:, 1] += 5.0
    det = _detection(sig, -np.full((n, 2), 3.0), np.full((n, 2), 3.0))
    fig = detection_figure(_episode(n), det)
    axes = fig.get_axes()
    assert len(axes) == 3  # two signal panels and the alarm panel
    assert [ax.get_ylabel() for ax in axes[:2]] == ["s1", "s2"]
    assert axes[0].get_yscale() == "linear"
    assert axes[0].collections[0].get_label() == "band"
    det.lower[:40], det.upper[:40] = -np.inf, np.inf  # no limit during a warm-up: still a band
    warm = detection_figure(_episode(n), det).get_axes()[0]
    assert warm.collections[0].get_label() == "band"
    path = save_png(fig, tmp_path / "sub" / "f.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_positive_statistic_with_silent_warm_up_is_drawn_on_a_log_axis() -> None:
    n = 300
    t2 = np.exp(np.random.default_rng(1).normal(size=(n, 1)))
    t2[:50] = 0.0  # a warm-up during which the statistic is not computed
    det = _detection(t2, np.full((n, 1), -np.inf), np.full((n, 1), 10.0))
    assert detection_figure(_episode(n), det).get_axes()[0].get_yscale() == "log"


def test_select_signals_and_bad_input() -> None:
    n = 300
    sig = np.zeros((n, 2))
    sig[:, 1] = 10.0  # always out of its band
    det = _detection(sig, -np.ones((n, 2)), np.ones((n, 2)))
    assert select_signals(det, 1) == [1]
    with pytest.raises(ValueError, match="max_signals=0 must be >= 1"):
        detection_figure(_episode(n), det, max_signals=0)
    with pytest.raises(ValueError, match="detection has 300 samples but the episode has 200"):
        detection_figure(_episode(200), det)
