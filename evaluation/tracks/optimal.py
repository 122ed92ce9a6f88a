"""The optimal-detector rows: what no detector can beat at the same false-alarm rate.

The other reference rows (:mod:`evaluation.tracks.oracle`) pair a perfect healthy model with a
generic alarm stage (EWMA + T², ``lrgf-glr``'s directional stage). None of them is a bound: an
alarm stage tuned to the fault beats them on small and slow faults. The two rows here read
even more than they do: the exact model, the true inputs and, for every fault of the track,
its noise-free trajectory on the episode's own seed at the size, onset and profile that
:meth:`~evaluation.tracks.track.Track.fault_spec` draws for that seed.

**optimal CUSUM (known fault)** (:data:`CUSUM_LABEL`). With h the healthy twin's noise-free
output (:meth:`~evaluation.tracks.track_data.TrackData.reference`, true inputs) and f = h + Δ a
fault's, the measurement noise is white and Gaussian with σ_c = noise_scale · (abs_c + rel_c
· |clean_c|) (:func:`fcc_env.integrator.noisy_kernel`), so each sample's log-likelihood ratio
of "faulty" against "healthy" is, over the eight Table 1 channels,

    LLR_t = Σ_c [ log(σ0/σ1) + (y − h)² / (2σ0²) − (y − f)² / (2σ1²) ]

(σ0, σ1 from h and f; they differ only on the relative-noise channel R_ar, where σ0 = σ1 the
log term vanishes and LLR_t reduces to Σ_c [(y−h)² − (y−f)²] / (2σ_c²)). Page's CUSUM
``S_t = max(0, S_{t−1} + LLR_t)`` alarms while ``S_t > limit``. Why a bound: for a known pre-
and post-change law, Page's CUSUM minimises the worst-case mean detection delay among all
detectors whose mean time between false alarms is at least the same (Lorden 1971; Moustakides
1986, exact optimality). Here the post-change law is known sample by sample (including its
onset, which only helps the detector), so no detector reading the same episode can detect that
change faster on average at that false-alarm level. Two caveats: (1) our r_fd target (a share
of healthy samples alarmed) is a proxy for the mean time between false alarms, not the same
quantity (alarms come in streaks), so the comparison is at the same r_fd, not the same ARL;
(2) with the change time known, Page's test is no longer the unique optimum (a Neyman-Pearson
sum from the onset can do better on some criteria), which makes this a strong reference rather
than a tight bound. On a track with several faults the detector does not know which: a bank,
one CUSUM per fault, alarming when any exceeds one common limit (all in nats). In closed loop
the noise feeds back through the controllers into the inputs, so h + Δ is the fault's effect at
the inputs the controllers chose in the faulty simulation: a close reference, not a bound.

**GLR (known type, unknown size)** (:data:`GLR_LABEL`): the fault's signature Δ at its drawn
size, but its size unknown. The alternative h + θΔ, θ ≥ 0 unknown, tested by the
window-limited GLR over the last :data:`GLR_WINDOW` samples (:func:`window_glr`),
``max_k (Σ_{j=k..t} Δ_jᵀΣ⁻¹(y_j − h_j))₊² / (2 Σ_{j=k..t} Δ_jᵀΣ⁻¹Δ_j)``, Σ the healthy noise
covariance. It adds what knowing the size is worth: the gap between the two rows is the price
of an unknown magnitude, which every real detector pays; a detector's gap to the GLR row is
what its model and its fault directions cost.

Both limits are set on healthy episodes of the track's validation seeds, never test seeds, at
every reference row's target (:data:`evaluation.tracks.oracle.REFERENCE_TARGET`), as the empirical
quantile of the bank's statistic.

>>> round(float(log_likelihood_ratio(np.zeros((1, 1)), np.zeros((1, 1)),
...     np.ones((1, 1)), np.ones((1, 1)), np.ones((1, 1)))[0]), 3)
-0.5
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Sequence
from enum import StrEnum

import numba
import numpy as np

from diagnosers.detection import Detection
from diagnosers.episode.record import Episode
from diagnosers.stages.alarm import CUSUM, LimitMethod, calibrate_limit
from evaluation.tracks.track_data import TrackData
from fcc_common.validation import Integer, Options, Real, check
from fcc_env.params import MEASUREMENT_NAMES
from fcc_env.plant import NOISE_STD_ABS, NOISE_STD_REL

__all__ = [
    "CUSUM_LABEL",
    "GLR_LABEL",
    "GLR_WINDOW",
    "SIGNATURE_CACHE",
    "FaultSignatures",
    "KnownFaultBank",
    "KnownFaultStatistic",
    "cusum",
    "log_likelihood_ratio",
    "noise_std",
    "window_glr",
]

#: The label of the Page CUSUM bank on the known fault trajectories.
CUSUM_LABEL = "optimal CUSUM (known fault)"
#: The label of the window-limited GLR over the fault's size.
GLR_LABEL = "GLR (known type, unknown size)"
#: Samples the GLR looks back for the start of the change (1000: as long as the shortest
#: incipient ramps, so a ramp's signature is seen whole; beyond it a start changes little).
GLR_WINDOW = 1000
#: Seeds whose signatures are kept: more than a track's faulty seeds per fault (20), so each
#: faulty seed's signatures are simulated at most twice (healthy cells come first).
SIGNATURE_CACHE = 64


class KnownFaultStatistic(StrEnum):
    """The statistic of a :class:`KnownFaultBank`."""

    CUSUM = "cusum"
    GLR = "glr"


def noise_std(clean: np.ndarray, noise_scale: float) -> np.ndarray:
    """The measurement noise std of each Table 1 sample of ``clean`` ``(T, 8) -> (T, 8)``:
    ``noise_scale · (abs + rel · |clean|)``, the env's model (R_ar relative, the rest absolute).
    """
    return noise_scale * (NOISE_STD_ABS + NOISE_STD_REL * np.abs(clean))


def log_likelihood_ratio(
    y: np.ndarray, h: np.ndarray, f: np.ndarray, sigma_h: np.ndarray, sigma_f: np.ndarray
) -> np.ndarray:
    """Per sample, log p(y | f, σ_f) − log p(y | h, σ_h) of independent Gaussian channels.

    Shape: ``y``, ``h``, ``f``, ``sigma_h``, ``sigma_f`` ``(T, c)`` (or broadcastable) ->
    ``(T,)``, summed over the channels.
    """
    log_ratio = np.log(sigma_h) - np.log(sigma_f)
    return np.sum(
        log_ratio + (y - h) ** 2 / (2.0 * sigma_h**2) - (y - f) ** 2 / (2.0 * sigma_f**2), axis=-1
    )


def cusum(llr: np.ndarray) -> np.ndarray:
    """Page's CUSUM ``S_t = max(0, S_{t−1} + LLR_t)``, ``S_{−1} = 0``, per column
    (:class:`diagnosers.stages.alarm.CUSUM` without drift). Shape: ``(T, k) -> (T, k)``."""
    return CUSUM(0.0).filter(np.asarray(llr, dtype=np.float64))


def window_glr(a: np.ndarray, b: np.ndarray, window: int) -> np.ndarray:
    """The window-limited GLR of a scaled known signature, per sample.

    With ``a_j = Δ_jᵀΣ⁻¹e_j`` (signature against residual) and ``b_j = Δ_jᵀΣ⁻¹Δ_j``,
    ``g_t = max_{t−window < k ≤ t} (Σ_{j=k..t} a_j)₊² / (2 Σ_{j=k..t} b_j)``, 0 where the
    signature is zero over the whole sum. Shape: ``a``, ``b`` ``(T,) -> (T,)``.
    """
    window = check("window", window, Integer(1))
    a = np.ascontiguousarray(a, dtype=np.float64)
    b = np.ascontiguousarray(b, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"a has shape {a.shape}, b {b.shape}; allowed: two equal shapes (T,)")
    return _window_glr(a, b, window)


@numba.njit(cache=True, nogil=True)
def _window_glr(a: np.ndarray, b: np.ndarray, window: int) -> np.ndarray:  # pragma: no cover
    out = np.zeros(a.shape[0])
    for t in range(a.shape[0]):
        sa = 0.0
        sb = 0.0
        best = 0.0
        for k in range(t, max(-1, t - window), -1):
            sa += a[k]
            sb += b[k]
            if sa > 0.0 and sb > 0.0:
                best = max(best, sa * sa / (2.0 * sb))
        out[t] = best
    return out


class FaultSignatures:
    """The noise-free signature Δ = f − h of every fault of a track on one seed (simulated).

    Fault ``g`` on seed ``s`` is the track's :meth:`~evaluation.tracks.track.Track.fault_spec`
    ``(g, s)`` simulated on ``s``; h its healthy twin with the true inputs (in closed loop the
    twin driven by the faulty episode's own noise-free record, as the physical-limit row's).
    Keeps the last :data:`SIGNATURE_CACHE` seeds, shared by the rows scored together.
    """

    def __init__(self, data: TrackData) -> None:
        self.data = data
        self._cache: OrderedDict[int, list[np.ndarray]] = OrderedDict()

    def __getstate__(self) -> dict[str, object]:
        """Pickled without the kept signatures (a fitted row travels to workers light)."""
        return {"data": self.data, "_cache": OrderedDict()}

    @property
    def faults(self) -> tuple[str, ...]:
        return self.data.track.faults

    def of(self, seed: int) -> list[np.ndarray]:
        """Per fault of the track, Δ ``(T_g, 8)`` on the Table 1 channels (``T_g`` the faulty
        episode's length; empty when it ended before the onset)."""
        if seed in self._cache:
            self._cache.move_to_end(seed)
            return self._cache[seed]
        out = []
        twin = None if self.data.track.closed_loop else self.data.reference(seed)
        for fault in self.faults:
            ep = self.data.load_test(fault, seed).episode
            if ep.fault_onset is None or ep.y_clean is None:
                out.append(np.zeros((0, len(MEASUREMENT_NAMES))))
                continue
            idx = [ep.channels.index(c) for c in MEASUREMENT_NAMES]
            clean = np.asarray(ep.y_clean, dtype=np.float64)
            h = twin if twin is not None else self.data.reference(seed, clean)
            # the signature ends with the shorter run: a healthy twin can trip where the faulty
            # plant does not (incipient seed 59 at sample 1389), and past its end no healthy
            # alternative exists to tell apart (KnownFaultBank.scores reads zeros there)
            n = min(clean.shape[0], h.shape[0])
            delta = clean[:n, idx] - h[:n]
            delta[: ep.fault_onset] = 0.0  # the twin equals the episode up to the onset
            out.append(delta)
        self._cache[seed] = out
        if len(self._cache) > SIGNATURE_CACHE:
            self._cache.popitem(last=False)
        return out


class KnownFaultBank:
    """A bank of known-fault tests, one per fault of the track, with one limit (nats).

    ``reference_of(episode)`` gives the healthy twin's noise-free Table 1 output of an
    episode (true inputs); ``signatures`` the faults' signatures on its seed. :meth:`fit`
    sets the limit on healthy episodes; :meth:`detect` scores an episode. Not a diagnoser:
    it reads what no diagnoser may.

    Args:
        statistic: ``"cusum"`` (Page's CUSUM of the exact LLR) or ``"glr"`` (window-limited
            GLR over the size).
        false_alarm_target: share of healthy calibration samples allowed over the limit.
        window: the GLR's window [samples].
    """

    def __init__(
        self,
        signatures: FaultSignatures,
        reference_of: Callable[[Episode], np.ndarray],
        *,
        statistic: str,
        false_alarm_target: float,
        window: int = GLR_WINDOW,
    ) -> None:
        self.signatures = signatures
        self.reference_of = reference_of
        self.statistic = KnownFaultStatistic(
            check("statistic", statistic, Options(KnownFaultStatistic))
        )
        self.false_alarm_target = check(
            "false_alarm_target", false_alarm_target, Real(0.0, 0.5, closed="neither")
        )
        self.window = check("window", window, Integer(1))
        self.noise_scale = signatures.data.track.noise_scale

    def scores(self, episode: Episode) -> tuple[np.ndarray, np.ndarray]:
        """(the bank's statistic ``(T, n_faults)``, its per-sample increment: the LLR for the
        CUSUM, the signature's matched residual ``a_t`` for the GLR)."""
        if episode.seed is None:
            raise ValueError("episode.seed is None; allowed: the seed of a track episode")
        idx = [episode.channels.index(c) for c in MEASUREMENT_NAMES]
        y = np.asarray(episode.y, dtype=np.float64)[:, idx]
        T = y.shape[0]
        h = np.asarray(self.reference_of(episode), dtype=np.float64)[:T]
        sigma_h = noise_std(h, self.noise_scale)
        stats, steps = [], []
        for d in self.signatures.of(episode.seed):
            delta = np.zeros_like(h)
            n = min(T, d.shape[0])
            delta[:n] = d[:n]  # past the faulty simulation's end there is no alternative
            if self.statistic is KnownFaultStatistic.CUSUM:
                f = h + delta
                step = log_likelihood_ratio(y, h, f, sigma_h, noise_std(f, self.noise_scale))
                stats.append(cusum(step[:, None])[:, 0])
            else:
                step = np.sum(delta * (y - h) / sigma_h**2, axis=1)
                info = np.sum(delta**2 / sigma_h**2, axis=1)
                stats.append(window_glr(step, info, self.window))
            steps.append(step)
        return np.stack(stats, axis=1), np.stack(steps, axis=1)

    def fit(self, healthy: Sequence[Episode]) -> KnownFaultBank:
        """Set the limit: the ``1 − false_alarm_target`` quantile of the bank's largest
        statistic over ``healthy`` (validation) episodes."""
        if not healthy:
            raise ValueError("healthy is empty; allowed: at least one healthy episode")
        top = np.concatenate([self.scores(ep)[0].max(axis=1) for ep in healthy])
        limit = calibrate_limit(top[:, None], self.false_alarm_target, method=LimitMethod.EMPIRICAL)
        self.limit_ = float(limit[0])
        if not np.isfinite(self.limit_):  # a NaN limit would never alarm, silently
            raise ValueError(
                f"the {self.statistic.value} bank's limit is {self.limit_}: a healthy "
                "calibration episode's statistic is not finite (its reference or a fault's "
                "signature holds NaN or inf); allowed: finite statistics"
            )
        return self

    def detect(self, episode: Episode) -> Detection:
        stat, step = self.scores(episode)
        return Detection(
            alarm=(stat > self.limit_).any(axis=1),
            signal=stat,
            lower=np.full_like(stat, -np.inf),
            upper=np.full_like(stat, self.limit_),
            residual=step,
            signal_names=tuple(f"{self.statistic.value}[{f}]" for f in self.signatures.faults),
        )
