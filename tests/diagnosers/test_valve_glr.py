"""``valve-glr`` (diagnosers/loops/valve_glr.py): its GLRs against exact signals, the detector
on a synthetic quasi-steady loop with a valve that sticks (the Choudhury et al. 2005 model of
fcc_env/stiction.py) and on the closed-loop plant, and its contract."""

from __future__ import annotations

import numpy as np
import pytest

import diagnosers
import fcc_env
from diagnosers import Episode
from diagnosers.conformance import check_diagnoser
from diagnosers.loops.valve_statistics import onset_statistics
from fcc_env.stiction import StictionValve

CHANNELS = ("T_rx", "u_F", "T_rg2", "T_fp")


def test_the_stuck_glr_is_the_gaussian_llr_of_the_stuck_path() -> None:
    u = np.r_[np.zeros(40), 0.7 * np.arange(1.0, 31.0)]  # the command ramps from sample 40
    phi = -0.5 * (u[40:] - u[39])  # gain 0.5, stuck after sample 39
    r = np.r_[np.zeros(40), phi]
    s = onset_statistics(r, u, gain=0.5, sigma=0.2, reference=20, a_min=0.5)
    # a = 1 fits exactly at the true onset, where the GLR peaks: Σ φ² / (2 σ²), 30 samples back
    assert s.stuck == pytest.approx(np.sum(phi**2) / (2 * 0.04), rel=1e-9)
    assert (s.since, s.size) == (30, 1.0)
    # a model gain 5 % off fits a = 0.05 < a_min: far below any limit, however large the move
    # (an onset inside the ramp, whose reference mean the ramp moves, leaves a trace)
    off = onset_statistics(0.05 * r, u, gain=0.5, sigma=0.2, reference=20, a_min=0.5)
    assert off.stuck < 1.0 < 100.0 < s.stuck
    # a step of size b after 10 samples: (Σ z)² / (2 σ² n (1 + n / reference))
    step = np.r_[np.zeros(60), np.full(10, 0.3)]
    b = onset_statistics(step, np.zeros(70), gain=0.5, sigma=0.2, reference=20, a_min=0.5)
    assert b.bias == pytest.approx(3.0**2 / (2 * 0.04 * 10 * 1.5), rel=1e-9)
    assert (b.bias_since, b.bias_reference) == (10, 0.0)  # the step's onset and its r̄
    assert onset_statistics(r[:20], u[:20], gain=0.5, sigma=0.2, reference=20, a_min=0.5) == (
        0.0,
        0.0,
        0.0,
        0,
        0,
        0.0,
    )


def _loop(
    S: float = 0.0, onset: int | None = None, n: int = 2500, seed: int = 0, bias: float = 0.0
) -> Episode:
    """A quasi-steady loop shaped like the plant's T_rx loop (sample 10 s): T_rx = 0.25 °C per
    kg/s of valve position + 0.6 T_rg2 (a slow walk) − 0.1 T_fp, noise 0.3 °C on each reading,
    an integral-dominated PI law (Kc 0.26, Ts/τI 2.3) on the measurement, set-point steps of up
    to ±6 °C every 300 samples (from sample 0), the valve sticking (S, J = S/2) from
    ``onset``, or passing ``bias`` kg/s more than its command from ``onset`` when S = 0."""
    rng = np.random.default_rng(seed)
    u, e_prev, t_rg2, t_fp, sp = 400.0, 0.0, 700.0, 200.0, 520.0
    valve: StictionValve | None = None
    out = np.empty((n, 4))
    for k in range(n):
        if k % 300 == 0:
            sp = 520.0 + rng.uniform(-6.0, 6.0)
        if onset is not None and k == onset and S > 0.0:
            valve = StictionValve(u)
        position = u if valve is None else valve.move(u, S, S / 2)
        if onset is not None and k >= onset:
            position += bias
        t_rg2 += rng.normal(0.0, 0.05)
        t_rx = 0.25 * position + 0.6 * t_rg2 - 0.1 * t_fp - 0.0
        y = np.array([t_rx, u, t_rg2, t_fp]) + rng.normal(0.0, 0.3, 4) * [1, 0, 1, 1]
        out[k] = y
        e = sp - y[0]
        u += 0.26 * (e - e_prev) + 0.6 * e  # the command for the next sample
        e_prev = e
    return Episode(out, channels=CHANNELS, sample_time_s=10.0)


@pytest.fixture(scope="module")
def synthetic() -> dict[str, list[Episode]]:
    return {
        "train": [_loop(seed=1), _loop(seed=2)],
        "healthy": [_loop(seed=s, n=2400) for s in (10, 11, 12)],
        # the onset 20 samples before a set-point step, whose moves the valve does not pass
        "stuck": [_loop(S=20.0, onset=1480, n=1700, seed=s) for s in (20, 21, 22)],
        "short": [_loop(S=20.0, onset=480, n=700, seed=23)],
    }


def test_a_valve_that_sticks_is_found_within_tens_of_samples(synthetic) -> None:
    d = diagnosers.make("valve-glr").fit(synthetic["train"])
    assert d.gain_ == pytest.approx(0.25, rel=0.05)  # the loop's own gain, from healthy data
    for ep in synthetic["healthy"]:
        assert not d.detect(ep).alarm.any()
    for ep in synthetic["stuck"]:
        alarm = d.detect(ep).alarm
        assert not alarm[:1480].any()
        assert alarm[1480:1540].any()


def test_a_valve_bias_stays_alarmed_after_the_loop_has_taken_it_out(synthetic) -> None:
    d = diagnosers.make("valve-glr").fit(synthetic["train"])
    ep = _loop(onset=1000, n=1800, seed=30, bias=20.0)  # 5 °C of residual, for good
    det = d.detect(ep)
    assert not det.alarm[:1000].any()
    # alarmed from the sample after its onset (a GLR of about 100 on the onset's own) to the
    # end, the set-point steps at 1200 and 1500 included; the windowed test alone forgets it
    # once the onset leaves its window
    assert det.alarm[1001:].all()
    windowed = diagnosers.make("valve-glr", hold=0).fit(synthetic["train"]).detect(ep).alarm
    assert windowed[1001] and not windowed[1100:].any()
    # the held GLR reads the step against the reference mean kept from before its onset
    assert det.signal[1500, 4] > 10 * d.hold_threshold


def test_a_transient_is_held_only_while_it_lasts(synthetic) -> None:
    d = diagnosers.make("valve-glr").fit(synthetic["train"])
    ep = synthetic["healthy"][0]
    y = np.array(ep.y, copy=True)
    y[1000:1020, 0] += 3.0  # the residual steps up by 3 °C (about 8 σ) for 20 samples
    alarm = d.detect(Episode(y, channels=CHANNELS, sample_time_s=10.0)).alarm
    assert alarm[1000:1010].any()
    # released once the latest samples are back at the kept mean; the step back down, whose
    # reference mean holds the transient, is not held in its turn
    assert not alarm[1100:].any()


@pytest.mark.parametrize("name", ["valve-glr", "valve-glr-partial"])
def test_it_keeps_the_contract(name: str, synthetic) -> None:
    check_diagnoser(diagnosers.make(name), train=synthetic["train"], test=synthetic["short"][0])


def test_the_partial_preset_is_the_family_with_a_lower_bound_on_the_share() -> None:
    from diagnosers.loops.valve_glr import ValveGLR

    d = diagnosers.make("valve-glr-partial")
    assert type(d).__mro__[1] is ValveGLR
    assert d.get_params() == ValveGLR(a_min=0.5).get_params()


def test_on_the_plant_a_sticking_valve_is_found_before_its_limit_cycle() -> None:
    plant = fcc_env.PlantConfig.build(regulatory=True)
    train = Episode.from_batch(fcc_env.simulate_episodes([1000, 1001], 1500, plant=plant))
    d = diagnosers.make("valve-glr").fit(train)
    stiction = fcc_env.FaultSpec(scenario="valve-stiction", magnitude=0.1, onset=500)
    b = fcc_env.simulate_episodes([5000, 5001], 1000, fault=stiction, plant=plant)
    for ep in Episode.from_batch(b):
        alarm = d.detect(ep).alarm
        # lab/stiction-detection.md: 3-40 samples on 20 validation episodes; the limit
        # cycle's monitors need hundreds
        assert not alarm[:500].any() and alarm[500:560].any()


def test_bad_settings_and_records_are_refused_by_name(synthetic) -> None:
    train = synthetic["train"]
    with pytest.raises(ValueError, match=r"a_min=0.0 is outside the allowed range"):
        diagnosers.make("valve-glr", a_min=0.0).fit(train)
    with pytest.raises(ValueError, match=r"regressors=\['T_rx'\] is outside the allowed range"):
        diagnosers.make("valve-glr", regressors=["T_rx"]).fit(train)
    with pytest.raises(ValueError, match=r"missing \['T_d1'\]"):
        diagnosers.make("valve-glr", regressors=["T_d1"]).fit(train)
    with pytest.raises(ValueError, match=r"hold_threshold=300.0 is outside the allowed range"):
        diagnosers.make("valve-glr", hold_threshold=300.0).fit(train)
    open_loop = Episode.from_batch(fcc_env.simulate_episodes([1000], 300))
    with pytest.raises(ValueError, match=r"missing \['u_F'\]"):
        diagnosers.make("valve-glr").fit(open_loop)
