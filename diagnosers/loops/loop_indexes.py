"""The signal algebra of the loop monitors: an oscillation's regularity and Horch's test.

Both work on one window of a control loop's data (a few cycles of the oscillation sought),
linearly detrended first (:func:`detrended`): a slow drift of the operating point (the feed, the
other loop) is not an oscillation, and a trend would put a spurious even part into the
correlations.

* :func:`acf_regularity`: N. F. Thornhill, B. Huang, H. Zhang, "Detection of multiple
  oscillations in control loops", *Journal of Process Control* 13 (2003) 91–100. The zero
  crossings of the autocorrelation function (ACF) of an oscillating signal come at regular
  intervals, while those of noise or of the decaying responses of a healthy loop do not. With
  ``T_p`` the intervals between alternate zero crossings (each one period), the regularity is
  ``r = mean(T_p) / (3·std(T_p))``; ``r > 1`` is the paper's oscillation (the periods' spread
  within a third of their mean). Working on the ACF rather than on the signal is what makes
  the test robust to noise: white measurement noise only adds a spike at lag zero. The
  ACF's height one period on says how strong the oscillation is against the rest of the
  window; the monitors also ask for it (stated, not the paper's: on the plant a healthy
  loop's ACF crosses zero regularly now and then at noise level, peak below 0.25).
* :func:`horch_phase`: A. Horch, "A simple method for detection of stiction in control valves",
  *Control Engineering Practice* 7 (1999) 1221–1231. In an oscillating loop with a sticking
  valve and integral action, the controller output is a ramp (the integral) while the
  controlled variable jumps at each slip: the two are a quarter period apart and their
  cross-correlation function (CCF) is *odd* (zero at lag zero). An oscillation from outside
  the valve (an external disturbance, an aggressive tuning) leaves the controller output
  following the controlled variable, and the CCF is *even* (an extremum at lag zero). The
  phase returned is ``arccos(|c(0)| / max|c(τ)|)`` over one period of lags: π/2 for an odd
  CCF, 0 for an even one (for a CCF ``cos(ωτ + φ)`` it is ``|φ|`` folded into [0, π/2]).
  Horch's test assumes a self-regulating process (true of the riser outlet temperature, which
  follows the valve at once); an integrating process needs his second test, not built here.
  It also assumes that the proportional action dominates at the oscillation's frequency: with
  an integral-dominated controller (the plant's T_rx loop, ``Ts/τ_I = 2.3``) the controller
  output lags the control error by about a quarter period whatever the cause, so a slow
  external sinusoid reads odd too (measured in ``lab/stiction-detection.md``).
* :func:`shape_index`: Q. P. He, J. Wang, M. Pottmann, S. J. Qin, "A curve fitting method for
  detecting valve stiction in oscillating control loops", *Ind. Eng. Chem. Res.* 46 (2007)
  4549–4560. Under stiction in a self-regulating loop the controller output is a triangle
  wave (the integral ramps it while the valve sticks), under an external sinusoid a sine.
  Each half cycle of the controller output is fitted with a triangle and with a sine; the
  index ``SI = MSE_sine / (MSE_sine + MSE_triangle)`` is near 1 for a triangle, near 0 for a
  sine; the paper reads ``SI ≤ 0.4`` as no stiction and ``SI ≥ 0.6`` as stiction. Simplified
  here (stated): both fits are symmetric humps over the half cycle between two zero
  crossings (amplitude and offset free), the output's trend removed with a moving average of
  one period first.
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.signal import correlate, detrend

__all__ = ["acf_regularity", "detrended", "horch_phase", "shape_index", "zero_crossings"]


def detrended(x: np.ndarray) -> np.ndarray:
    """``x`` ``(n,)`` less its least-squares straight line (``scipy.signal.detrend``)."""
    return detrend(np.asarray(x, dtype=np.float64), type="linear")


def zero_crossings(a: np.ndarray) -> np.ndarray:
    """Where ``a`` ``(n,)`` changes sign, interpolated linearly between samples (in samples
    from the first, ascending); a sample exactly at zero counts with the positive ones."""
    a = np.asarray(a, dtype=np.float64)
    neg = a < 0.0
    k = np.flatnonzero(neg[1:] != neg[:-1])
    return k + a[k] / (a[k] - a[k + 1])


def acf_regularity(
    e: np.ndarray, max_lag: int, n_crossings: int, min_period: float
) -> tuple[float, float, float]:
    """Thornhill et al. (2003)'s regularity ``r`` of window ``e`` ``(n,)``, its mean period
    (in samples) and the ACF's first peak (its largest value between the second and third
    zero crossings, one period on: how much of the window's variance the oscillation holds;
    white noise's is about ``1/√n``): module docstring.

    ``max_lag``: the ACF's last lag (a fraction of the window, where the estimate is still
    good; the paper uses the ACF's first zero crossings only); ``n_crossings`` (≥ 4): how
    many of the first zero crossings make the ``n_crossings − 2`` period estimates. A window
    whose ACF crosses zero fewer times, or whose mean period is below ``min_period``
    (samples: faster than the loop can oscillate, the measurement noise), gets ``r = 0``
    and period and peak ``nan``; a constant window too.
    """
    e = np.asarray(e, dtype=np.float64)
    n = e.shape[0]
    none = (0.0, float("nan"), float("nan"))
    if n < 2 or np.ptp(e) == 0.0:  # detrending a constant leaves round-off, not a signal
        return none
    x = detrended(e)
    ss = float(x @ x)
    acf = correlate(x, x, mode="full", method="fft")[n - 1 : n + max_lag] / ss
    z = zero_crossings(acf)
    if z.shape[0] < n_crossings:
        return none
    z = z[:n_crossings]
    periods = z[2:] - z[:-2]
    mean = float(periods.mean())
    if mean < min_period:
        return none
    spread = float(periods.std())
    peak = float(acf[int(np.ceil(z[1])) : int(np.floor(z[2])) + 1].max(initial=0.0))
    # a perfectly regular ACF (a pure tone) has no spread: cap r instead of dividing by zero
    return (min(mean / (3.0 * spread), 1e6) if spread > 0.0 else 1e6), mean, peak


def horch_phase(op: np.ndarray, e: np.ndarray, period: float) -> float:
    """Horch (1999)'s test on a window of controller output ``op`` and control error ``e``
    (both ``(n,)``) oscillating with ``period`` samples: the CCF's phase at lag zero in
    radians, π/2 odd (stiction), 0 even (module docstring). Lags span ± half a period."""
    u, y = detrended(op), detrended(e)
    n = u.shape[0]
    lag = int(min(max(round(period / 2.0), 1), n - 1))
    c = correlate(y, u, mode="full", method="direct")[n - 1 - lag : n + lag]
    peak = float(np.max(np.abs(c)))
    if peak == 0.0:
        return 0.0
    return float(np.arccos(min(abs(float(c[lag])) / peak, 1.0)))


def _hump_misfit(segment: np.ndarray, hump: np.ndarray) -> float:
    """The residual sum of squares of ``segment ≈ a·hump + b`` (least squares)."""
    basis = np.column_stack([hump, np.ones_like(hump)])
    coef, *_ = np.linalg.lstsq(basis, segment, rcond=None)
    return float(np.sum((segment - basis @ coef) ** 2))


def shape_index(op: np.ndarray, period: float) -> float:
    """He et al. (2007)'s stiction index of a window of controller output ``op`` ``(n,)``
    oscillating with ``period`` samples: ``MSE_sine / (MSE_sine + MSE_triangle)`` over its
    complete half cycles (module docstring); ``nan`` with fewer than two half cycles."""
    p = max(round(period), 3)
    x = detrended(op)
    x = x - uniform_filter1d(x, p, mode="nearest")  # the trend left within the window
    neg = x < 0.0
    cuts = np.flatnonzero(neg[1:] != neg[:-1]) + 1
    sine = triangle = 0.0
    halves = 0
    for a, b in itertools.pairwise(cuts):
        m = int(b - a)
        if m < max(p // 4, 3):  # a noise crossing, not a half cycle
            continue
        t = (np.arange(m) + 0.5) / m
        sine += _hump_misfit(x[a:b], np.sin(np.pi * t))
        triangle += _hump_misfit(x[a:b], 1.0 - np.abs(2.0 * t - 1.0))
        halves += 1
    if halves < 2 or sine + triangle == 0.0:
        return float("nan")
    return sine / (sine + triangle)
