"""The valve-stiction model (fcc_env.stiction) against what Choudhury, Thornhill & Shah (2005)
report of it: the four phase-plot shapes under a sinusoidal command (pure deadband,
undershoot, no offset, overshoot), the stickband on a restart in the same direction, and the
limit cycles in a PI loop (present with stiction on a self-regulating and an integrating
process, absent without; a pure deadband cycles only with the integrating one), detected by
zero crossings."""

from __future__ import annotations

import numpy as np
import pytest

from fcc_env.stiction import StictionValve, valve_response

A, S = 10.0, 4.0
T = np.arange(2000)
SINE = A * np.sin(2 * np.pi * T / 400)  # five cycles; steps up to 0.157 (the largest |Δx|)
STEP = float(np.abs(np.diff(SINE)).max())


def _moving(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Samples where the valve moved with the command (no slip, no stick)."""
    dx, dy = np.diff(x), np.diff(y)
    return np.flatnonzero(np.isclose(dy, dx, atol=1e-12) & (dx != 0)) + 1


@pytest.mark.parametrize(
    ("J", "case"), [(0.0, "deadband"), (2.0, "undershoot"), (4.0, "no offset"), (6.0, "overshoot")]
)
def test_the_phase_plot_of_each_case(J: float, case: str) -> None:
    y = valve_response(SINE, S, J)
    moving = _moving(SINE, y)
    assert moving.size > 200, case  # the valve follows the command between the sticks
    # while moving, the valve sits (S − J)/2 behind the command: lags, meets it, or leads
    sign = np.sign(np.diff(SINE))[moving - 1]
    np.testing.assert_allclose(y[moving] - SINE[moving], -sign * (S - J) / 2, atol=1e-12)
    # the slips after the first peak (the valve starts at rest, at the command): jumps of J
    # (plus at most one command step past the band) at each of the 10 reversals; none if J = 0
    dy = np.abs(np.diff(y[100:]))
    jumps = dy[dy > STEP + 1e-9]
    if J == 0.0:
        assert jumps.size == 0 and dy.max() <= STEP + 1e-12
    else:
        assert jumps.size == 10
        assert (jumps >= J - 1e-9).all() and (jumps <= J + STEP + 1e-9).all()
    # the position's swing: the command's amplitude less (or, overshoot, more) (S − J)/2
    steady = y[500:]
    assert steady.max() == pytest.approx(A - (S - J) / 2, abs=STEP)
    assert steady.min() == pytest.approx(-A + (S - J) / 2, abs=STEP)


def test_a_reversal_waits_for_the_band_S() -> None:
    x = np.concatenate([np.linspace(0, 5, 51), np.linspace(5, -5, 101)])
    y = valve_response(x, S=3.0, J=1.0)
    top = 50  # the command peaks at sample 50, then falls 0.1 a sample
    stuck = np.flatnonzero(y[top:] == y[top]) + top
    # stuck until the command has fallen by more than S from where the valve stuck
    assert x[stuck[-1]] >= 5.0 - 3.0 - 1e-9 and x[stuck[-1] + 1] < 5.0 - 3.0
    assert y[stuck[-1] + 1] == pytest.approx(x[stuck[-1] + 1] + (3.0 - 1.0) / 2)


def test_a_stop_then_the_same_direction_needs_only_the_stickband_J() -> None:
    up = np.linspace(0, 5, 51)
    x = np.concatenate([up, np.full(20, 5.0), 5.0 + np.linspace(0.1, 3, 30)])
    y = valve_response(x, S=3.0, J=1.0)
    restart = 71 + np.flatnonzero(np.diff(y[70:]) != 0)[0]  # the first move after the hold
    assert x[restart] - 5.0 > 1.0 and x[restart - 1] - 5.0 <= 1.0 + 1e-9  # J, not S
    assert y[restart] - y[70] == pytest.approx(x[restart] - 5.0, abs=1e-9)  # a slip of ~J


def test_noise_inside_the_band_never_moves_the_valve() -> None:
    rng = np.random.default_rng(0)
    x = 0.4 * rng.uniform(-1, 1, 500)  # reverses every few samples, inside S = 1
    assert np.ptp(valve_response(x, S=1.0, J=0.5)) == 0.0
    # a drift under the same noise slips the valve (the stuck point stays latched)
    drift = x + np.linspace(0, 5, 500)
    assert np.ptp(valve_response(drift, S=1.0, J=0.5)) > 3.0


def _pi_loop(S: float, J: float, integrating: bool, n: int = 4000) -> np.ndarray:
    """A PI loop (sample 1 s, set point step at 10 s) through a sticking valve on a
    self-regulating FOPTD process 3 e^(−10 s)/(10 s + 1), PI 0.2 (1 + 1/(10 s)), or on an
    integrating one 0.1 e^(−2 s)/s, PI 1.0 (1 + 1/(30 s)); the process output."""
    gain, tau, delay, kc, ti = (
        (0.1, 0.0, 2, 1.0, 30.0) if integrating else (3.0, 10.0, 10, 0.2, 10.0)
    )
    a = np.exp(-1.0 / tau) if tau else 1.0
    valve, out, u, e_prev, y = StictionValve(0.0), np.empty(n), 0.0, 0.0, 0.0
    queue = [0.0] * (delay + 1)
    for k in range(n):
        e = (1.0 if k >= 10 else 0.0) - y
        u += kc * (e - e_prev) + kc / ti * e
        e_prev = e
        queue.append(valve.move(u, S, J))
        v = queue.pop(0)
        y = a * y + gain * (1 - a) * v if tau else y + gain * v
        out[k] = y
    return out


def _cycle(y: np.ndarray) -> tuple[float, float]:
    """Half peak-to-peak amplitude and period (zero crossings about the mean) of the last half."""
    z = y[len(y) // 2 :] - y[len(y) // 2 :].mean()
    amp = float(np.ptp(z) / 2)
    zc = np.flatnonzero(np.diff(np.sign(z)) != 0)
    period = float(2 * np.diff(zc).mean()) if zc.size > 4 else np.inf
    if zc.size > 4:  # a limit cycle repeats: its half periods agree
        half = np.diff(zc)
        assert half.std() / half.mean() < 0.2, (half.mean(), half.std())
    return amp, period


@pytest.mark.parametrize("integrating", [False, True])
def test_a_pi_loop_cycles_with_stiction_and_settles_without(integrating: bool) -> None:
    amp, period = _cycle(_pi_loop(0.0, 0.0, integrating))
    assert amp < 1e-6 and period == np.inf  # a linear loop settles
    for J in (2.0, 5.0, 7.0):  # undershoot, no offset, overshoot: each cycles
        amp, period = _cycle(_pi_loop(5.0, J, integrating))
        assert amp > 1.0 and 20.0 < period < 400.0, (J, amp, period)


def test_a_pure_deadband_cycles_only_with_an_integrating_process() -> None:
    amp, period = _cycle(_pi_loop(5.0, 0.0, integrating=False))
    assert amp < 1e-6 and period == np.inf
    amp, period = _cycle(_pi_loop(5.0, 0.0, integrating=True))
    assert amp > 1.0 and 20.0 < period < 400.0


def test_bad_parameters_are_refused_by_name() -> None:
    with pytest.raises(ValueError, match=r"S=-1.*deadband plus stickband"):
        valve_response(np.zeros(3), S=-1.0, J=0.0)
    with pytest.raises(ValueError, match="commands must be a non-empty 1-D array"):
        valve_response(np.zeros((2, 2)), S=1.0, J=0.0)
