"""Figures (evaluation.reports.plots): layout, scales and input checks."""

from __future__ import annotations

import numpy as np
import pytest

from diagnosers.detection import Detection
from diagnosers.episode.record import Episode
from evaluation.reports.plots import (
    ALARM_LABEL,
    EXIT_LABEL,
    axis_label,
    detection_figure,
    save_png,
    select_signals,
)
from evaluation.reports.tables import table_legend
from evaluation.tracks.board_tables import track_legend
from fcc_env.plotting import plot_scenarios, scenarios_figure, trend_figure, trend_image


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
    fig = detection_figure(_episode(n), det, units={"s1": "°C", "s2": "t/h"})
    axes = fig.get_axes()
    assert len(axes) == 3  # two signal panels and the alarm panel
    assert [ax.get_ylabel() for ax in axes[:2]] == ["s1 [°C]", "s2 [t/h]"]
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


def _strip_rows(fig) -> dict[str, np.ndarray]:
    """The strip's named on/off rows: label -> boolean per sample (the step line above its row)."""
    strip = fig.get_axes()[-1]
    return {
        line.get_label(): np.asarray(line.get_ydata()) > np.min(line.get_ydata())
        for line in strip.get_lines()
        if not line.get_label().startswith("_")
    }


def _legend_labels(fig) -> list[str]:
    return [t.get_text() for legend in fig.legends for t in legend.get_texts()]


def test_every_y_axis_has_a_unit_and_the_legend_names_the_alarm_shading() -> None:
    n = 300
    rng = np.random.default_rng(2)
    meas = 500.0 + rng.normal(size=(n, 2))
    det = Detection(np.zeros(n, bool), meas, meas - 3, meas + 3, np.zeros((n, 2)), ("T_rx", "R_ar"))
    stat = np.exp(rng.normal(size=(n, 2)))
    t2 = Detection(
        np.zeros(n, bool),
        stat,
        np.full((n, 2), -np.inf),
        np.full((n, 2), 9.0),
        stat,
        ("T2", "SPE"),
    )
    for d, want in ((det, ["T_rx [°C]", "R_ar [t/h]"]), (t2, ["T² [-]", "SPE [-]"])):
        fig = detection_figure(_episode(n), d)
        labels = [ax.get_ylabel() for ax in fig.get_axes()]
        assert labels[:2] == want
        assert all("[" in lab and "]" in lab for lab in labels), labels
        assert "[" in fig.get_axes()[-1].get_xlabel()
        # one figure legend (outside the panels, so it covers no data) with the alarm shading
        assert all(ax.get_legend() is None for ax in fig.get_axes())
        assert f"{ALARM_LABEL} (shaded)" in _legend_labels(fig)
        assert "fault onset" in _legend_labels(fig)


def test_axis_label_units() -> None:
    assert axis_label("T_rg2") == "T_rg2 [°C]"
    assert axis_label("T_rx [°C]") == "T_rx [°C]"  # already carries its unit
    assert axis_label("T2[ewma]") == "T² of EWMA residuals [-]"
    assert axis_label("ewma[T_rx]") == "EWMA of T_rx residual [-]"
    assert axis_label("F3") == "F3"  # unknown: no unit, never a guessed one
    assert axis_label("F3", {"F3": "kg/s"}) == "F3 [kg/s]"


def test_subtitle_names_the_shown_channels_and_why() -> None:
    n = 300
    sig = np.zeros((n, 8))
    sig[:, [2, 5, 7]] = 10.0  # these leave their limits
    names = tuple(f"c{i}" for i in range(8))
    det = Detection(np.ones(n, bool), sig, -np.ones((n, 8)), np.ones((n, 8)), sig, names)
    title = detection_figure(_episode(n), det, title="limits on f1").get_suptitle()
    assert title.splitlines()[0] == "limits on f1"
    assert "shown: c2, c5, c7 (3 of 8 monitored signals, those most often outside" in title
    det2 = Detection(
        det.alarm, sig[:, :2], det.lower[:, :2], det.upper[:, :2], sig[:, :2], names[:2]
    )
    assert "all 2 monitored signals shown" in detection_figure(_episode(n), det2).get_suptitle()


def test_band_figure_strip_shows_the_detector_alarms_and_band_exits_apart() -> None:
    n = 300
    rng = np.random.default_rng(4)
    y = rng.normal(size=(n, 2))
    lo, hi = np.full((n, 2), -1.5), np.full((n, 2), 1.5)
    exits = np.any((y < lo) | (y > hi), axis=1)
    bands = Detection(exits, y, lo, hi, y, ("T_rx [°C]", "T_rg1 [°C]"))
    alarm = np.zeros(n, bool)
    alarm[200:260] = True  # the detector raises far fewer alarms than there are band exits
    stat = np.ones((n, 1))
    decisions = Detection(
        alarm, stat, np.full((n, 1), -np.inf), np.full((n, 1), 5.0), stat, ("T2[ewma]",)
    )
    assert exits.sum() > 20 and not np.array_equal(exits, alarm)
    fig = detection_figure(_episode(n), bands, decisions=decisions)
    rows = _strip_rows(fig)
    assert set(rows) == {ALARM_LABEL, EXIT_LABEL}
    np.testing.assert_array_equal(rows[ALARM_LABEL], alarm)
    np.testing.assert_array_equal(rows[EXIT_LABEL], exits)
    assert EXIT_LABEL in _legend_labels(fig)
    assert [t.get_text() for t in fig.get_axes()[-1].get_yticklabels()] == [
        "band exit",
        "detector alarm",
    ]
    # the shading in the panels is the detector's: one span, 200..259, not the scattered exits
    shade = fig.get_axes()[0].collections[-1]
    xs = np.concatenate([p.vertices[:, 0] for p in shade.get_paths()])
    assert xs.min() == 200 and xs.max() == 259
    # without a separate view the strip has only the detector's row
    alone = _strip_rows(detection_figure(_episode(n), decisions))
    assert set(alone) == {ALARM_LABEL}
    np.testing.assert_array_equal(alone[ALARM_LABEL], alarm)
    short = Detection(exits[:200], y[:200], lo[:200], hi[:200], y[:200], bands.signal_names)
    with pytest.raises(ValueError, match="decisions has 300 samples but the episode has 200"):
        detection_figure(_episode(200), short, decisions=decisions)


def test_env_trend_frame_names_scenario_time_and_onset() -> None:
    y = 500.0 + np.random.default_rng(5).normal(size=(200, 8))
    before = trend_figure(y, 199, 10.0, env_id="FCC-v0", scenario="f1", fault_onset=250)
    after = trend_figure(y, 299, 10.0, scenario="f1", fault_onset=250)
    healthy = trend_figure(y, 299, 10.0, scenario="nominal")
    assert before.get_suptitle() == "FCC-v0, sample 199, t = 0.55 h\nscenario f1, no fault yet"
    assert after.get_suptitle().startswith("sample 299, t = 0.83 h\n")  # data without an env
    assert after.get_suptitle().endswith("scenario f1, fault since sample 250 (0.69 h)")
    assert healthy.get_suptitle().endswith("scenario nominal, no fault")
    axes = after.get_axes()
    assert all("[" in ax.get_ylabel() and "]" in ax.get_ylabel() for ax in axes)
    onset_lines = [ln for ln in axes[0].get_lines() if ln.get_label() == "fault onset"]
    assert len(onset_lines) == 1 and onset_lines[0].get_xdata()[0] == 250 * 10.0 / 3600
    assert not [ln for ln in before.get_axes()[0].get_lines() if ln.get_label() == "fault onset"]
    assert [t.get_text() for lg in after.legends for t in lg.get_texts()] == ["fault onset"]
    # the rasterised frames differ by scenario and by time, at one fixed size
    frames = [
        trend_image(y, 299, 10.0, scenario="f1", fault_onset=250),
        trend_image(y, 299, 10.0, scenario="nominal"),
        trend_image(y, 399, 10.0, scenario="nominal"),
    ]
    assert len({f.shape for f in frames}) == 1 and frames[0].dtype == np.uint8
    assert not np.array_equal(frames[0], frames[1])
    assert not np.array_equal(frames[1], frames[2])


def test_demo_scenarios_figure_units_and_legend_outside(tmp_path) -> None:
    y = 500.0 + np.random.default_rng(6).normal(size=(400, 8))
    episodes = {"nominal": y, "f1": y + 1.0, "f3": y - 1.0}
    onsets = {"nominal": None, "f1": 200, "f3": 210}
    fig = scenarios_figure(episodes, onsets, 10.0)
    axes = fig.get_axes()
    assert [ax.get_ylabel() for ax in axes] == [
        "T_rx [°C]",
        "T_rg1 [°C]",
        "T_rg2 [°C]",
        "T_d1 [°C]",
        "T_dg [°C]",
    ]
    assert axes[-1].get_xlabel() == "time [h]"
    assert all(ax.get_legend() is None for ax in axes)
    labels = [t.get_text() for lg in fig.legends for t in lg.get_texts()]
    assert labels == ["nominal", "f1", "f3", "fault onset: f1 0.56 h, f3 0.58 h"]
    path = plot_scenarios(episodes, onsets, 10.0, tmp_path / "demo" / "s.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_table_legends_define_metrics_units_and_dispersion_alike() -> None:
    classic, track = table_legend(10.0), track_legend(10.0)
    for text in (classic, track):
        assert text.startswith("Legend: r_fd: false detection rate")
        for term in ("r_td: true detection rate", "t_dt: detection time", "[samples]"):
            assert term in text
        assert "(1 sample = 10 s)" in text and "[0-1, lower is better]" in text
        assert "–: no value" in text
    assert "a ± b: mean ± standard deviation over the test seeds" in classic
    assert "a [lo, hi]: estimate and 95 % BCa bootstrap interval" in track
    assert "t_dt/oracle" in track and "missed/ended" in track
    # the metric definitions are worded once, the same way in both tables
    for metric in ("r_fd", "r_td"):
        assert _definition(classic, metric) in track
    assert "(1 sample" not in table_legend() and "(1 sample" not in track_legend()


def _definition(text: str, metric: str) -> str:
    start = text.index(f"{metric}: ")
    return text[start : text.index("]", start) + 1]
