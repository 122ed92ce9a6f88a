"""A bank of FCC state estimators, one per hypothesis, and their multiple-model posterior.

Each hypothesis is an :class:`~diagnosers.filters.FCCStateEstimator` on the same parameters:
the healthy one (``"nominal"``) as the state estimator is, and one per fault that also carries
the :class:`~fcc_env.FCCParams` fields that fault scales (:data:`fcc_env.faults.FAULTS`: f1
``rho_b``, f2 ``K_w1`` and ``K_w2``, f3 ``k_sigma``, f4 ``V_rx_sp_m3``) as random-walk states,
so a fault of unknown size is estimated rather than assumed. All hypotheses see the same
observation, so one compiled call (:func:`bank_run`) advances every filter of a sample, or of a
whole record: the per-call overhead of five separate streaming updates is paid once.

**Posterior** (multiple-model adaptive estimation, MMAE, with a switching prior): with ``p`` the
posterior after sample k − 1 and ``ℓ_h`` hypothesis h's innovation log-likelihood of sample k
(``−½(νᵀS⁻¹ν + log det S + 8 log 2π)``),

    p⁻ = (1 − ε) p + ε / H,        p_h ∝ p⁻_h exp(ℓ_h).

(with ``leave = ε / H``; in general nominal switches to each fault with ``ε / H`` and a fault to
each other hypothesis with ``leave``, see :func:`mmae_run`). The ``ε / H`` term
(``switch_prob``) is the probability that the plant switches hypothesis within a sample;
without it the posterior of a long healthy run would pin the fault hypotheses at 0 and never
move when a fault begins (it is a floor: no hypothesis falls below about ``ε / H`` before its
likelihood). The same floor caps every log-odds at about ``log(H / ε)``, so a posterior with
``leave = ε / H`` forgets the evidence of a fault's onset once the filters stop telling the
hypotheses apart; ``mmae`` makes ``leave`` far smaller. Why not IMM: IMM mixes the filters' states at every sample, which needs a common
state; here the fault filters carry extra parameter states, and mixing the healthy filter with
them would let a fault's parameter leak into the healthy hypothesis. The bank's filters stay
independent, so they can run as one batched call.

**Window NIS** (:func:`mmae_run`): the normalised innovation squared of each filter summed over
the last ``window`` samples, χ²(8 · window) while that hypothesis is right; the bank reports the
smallest over the hypotheses, least over the last ``window`` samples, so "no hypothesis has
explained the innovations for a window" is one limit test.

numba's cache checks only a compiled function's own file: after editing
:mod:`diagnosers.filters`, delete this package's ``__pycache__`` too.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from diagnosers.filters import FCCStateEstimator, UKFConfig
from diagnosers.filters.ukf_kernels import sigma_weights, workspace
from diagnosers.filters.ukf_model import fcc_sample
from fcc_common.validation import invalid
from fcc_env.faults import NOMINAL, fault_definition
from fcc_env.params import FCCParams
from fcc_env.physics import njit_kernel

__all__ = ["FilterBank", "bank_run", "calibrate_walks", "mmae_run"]

_LOG_2PI = math.log(2.0 * math.pi)


@njit_kernel
def bank_run(
    models, Ms, Ps, Y, qs, wts, r_abs, r_rel, gate_idx, gate_lin, gate, n_scratch, WHITE, LOGLIK
) -> None:
    """Every filter of the bank on the samples ``Y`` (T, n_obs), in order.

    ``models``, ``Ms`` (n_h,), ``Ps`` (n_h, n_h), ``qs``, ``wts``: tuples with one entry per
    hypothesis (their priors advance in place); out: ``WHITE`` (T, H, 8) the whitened
    innovations, ``LOGLIK`` (T, H) the innovations' Gaussian log-likelihood (0 on a skipped
    sample). One call per sample (streaming) or per record (batch) runs the same arithmetic.
    """
    ny = r_abs.shape[0]
    G = gate_idx.shape[0]
    innov, stdz = np.empty(ny), np.empty(ny)
    S = np.empty((ny, ny))
    jumps = np.empty(G, dtype=np.bool_)
    for h in range(len(Ms)):
        n = Ms[h].shape[0]
        ws = workspace(n, ny, n_scratch)
        post, post_sd = np.empty(n), np.empty(n)
        fixed = (qs[h], r_abs, r_rel, gate_idx, gate_lin, gate, wts[h])
        Ls = ws[5]
        for k in range(Y.shape[0]):
            white = WHITE[k, h]
            out = (innov, stdz, white, S, post, post_sd, jumps)
            status = fcc_sample(models[h], Ms[h], Ps[h], Y[k], fixed, ws, out)
            if status & 1:  # skipped: no evidence either way
                LOGLIK[k, h] = 0.0
                continue
            ll = -0.5 * ny * _LOG_2PI
            for i in range(ny):
                ll -= 0.5 * white[i] * white[i] + math.log(Ls[i, i])
            LOGLIK[k, h] = ll


@njit_kernel
def _mmae_step(loglik, p, jump, leave, out) -> None:
    """One sample's switching prior and Bayes update of ``p`` (in place; copied to ``out``)."""
    H = p.shape[0]
    top = -np.inf
    for h in range(H):
        top = max(top, loglik[h])
    faulty = 0.0
    for h in range(1, H):
        faulty += p[h]
    p0 = p[0]
    p[0] = p0 * (1.0 - jump * (H - 1)) + leave * faulty
    for h in range(1, H):
        p[h] = p[h] * (1.0 - leave * (H - 1)) + jump * p0 + leave * (faulty - p[h])
    total = 0.0
    for h in range(H):
        p[h] *= math.exp(loglik[h] - top)
        total += p[h]
    for h in range(H):
        p[h] /= total
        out[h] = p[h]


@njit_kernel
def mmae_run(LOGLIK, NIS, p, ring, best, pos, eps, leave, hold, POST, WIN) -> int:
    """The posterior and the persistent window NIS of samples ``LOGLIK``/``NIS`` (T, H).

    The switching prior (column 0 nominal): from nominal to each fault ``eps / H``; from a fault
    to each other hypothesis ``leave`` (``eps / H``: every hypothesis alike, a plain MMAE
    switching term; smaller: the evidence a fault gathered is not forgotten when the filters
    stop telling the hypotheses apart, see :class:`~diagnosers.isolation.mmae.MMAE`'s
    ``fault_leave_prob``).

    The posterior holds (``POST`` repeats ``p``) while fewer than ``hold`` samples have been
    seen: the filters' start-up, whose innovations are no evidence for a hypothesis.

    State carried between calls (in place): ``p`` (H,) the posterior, ``ring`` (W, H) the last W
    samples' NIS, ``best`` (W,) the last W window values; ``pos`` the samples seen so far
    (returned, advanced). Out: ``POST`` (T, H); ``WIN`` (T,): the smallest over the
    hypotheses of the NIS summed over the last W samples, and of that the least over the last
    W samples (NaN until 2W − 1 samples are seen): above a limit only when no hypothesis has
    explained a window for W samples in a row, so a fault filter's transient while its
    parameter converges is not taken for an unexplained fault.
    """
    H, W = p.shape[0], ring.shape[0]
    acc = np.empty(H)
    jump = eps / H  # from nominal to each fault
    for k in range(LOGLIK.shape[0]):
        if pos < hold:
            for h in range(H):
                POST[k, h] = p[h]
        else:
            _mmae_step(LOGLIK[k], p, jump, leave, POST[k])
        slot = pos % W
        for h in range(H):
            ring[slot, h] = NIS[k, h]
        pos += 1
        WIN[k] = np.nan
        if pos < W:
            continue
        for h in range(H):
            acc[h] = 0.0
        for j in range(W):  # summed afresh: a running sum would drift from the batch's
            for h in range(H):
                acc[h] += ring[j, h]
        smallest = np.inf
        for h in range(H):
            smallest = min(smallest, acc[h])
        best[(pos - W) % W] = smallest
        if pos - W + 1 < W:
            continue
        least = np.inf
        for j in range(W):
            least = min(least, best[j])
        WIN[k] = least
    return pos


@dataclass(frozen=True)
class FilterBank:
    """The hypotheses' estimators and what the compiled bank reads of them.

    Build with :meth:`build`; :meth:`start` gives a fresh streaming state, :meth:`run` filters
    samples from one.
    """

    hypotheses: tuple[str, ...]  # "nominal", then the faults
    estimators: tuple[FCCStateEstimator, ...]
    models: tuple = ()  # what the compiled bank reads, one entry per hypothesis
    qs: tuple = ()
    weights: tuple = ()

    def __post_init__(self) -> None:
        c = self.estimators[0].config
        set_ = object.__setattr__
        set_(self, "models", tuple(e.filter_model.model for e in self.estimators))
        set_(self, "qs", tuple(e.filter_model.q for e in self.estimators))
        set_(
            self,
            "weights",
            tuple(sigma_weights(e.n_states, c.alpha, c.beta, c.kappa) for e in self.estimators),
        )

    @classmethod
    def build(
        cls,
        params: FCCParams,
        config: UKFConfig,
        faults: tuple[str, ...],
        *,
        fault_walk_std_rel: Sequence[float],
        fault_initial_std_rel: float,
    ) -> FilterBank:
        """The bank of ``faults``' hypotheses on ``params``: each fault's filter estimates the
        parameters the fault registry says it scales, as random walks of relative standard
        deviation ``fault_walk_std_rel`` per sample (one per fault; prior
        ``fault_initial_std_rel``)."""
        if len(fault_walk_std_rel) != len(faults):
            raise ValueError(f"{len(fault_walk_std_rel)} walks for the {len(faults)} faults")
        ests = [FCCStateEstimator(params, config)]
        for f, walk in zip(faults, fault_walk_std_rel, strict=True):
            fields = fault_definition(f).parameters
            if not fields:
                raise invalid(
                    "faults",
                    faults,
                    "faults that scale FCCParams fields (fcc_env.FAULTS)",
                    f"{f!r} acts through hooks only: no parameter for its filter to estimate",
                )
            cfg = config.replace(
                parameters=fields,
                parameter_walk_std_rel=float(walk),
                parameter_initial_std_rel=fault_initial_std_rel,
            )
            ests.append(FCCStateEstimator(params, cfg))
        return cls(hypotheses=(NOMINAL, *faults), estimators=tuple(ests))

    @property
    def channels(self) -> tuple[str, ...]:
        return self.estimators[0].channels

    def start(self) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
        """Every filter's initial prior: ``(means, covariances)``, one entry per hypothesis."""
        pairs = [e.initial_prior(1) for e in self.estimators]
        return tuple(m[0].copy() for m, _ in pairs), tuple(P[0].copy() for _, P in pairs)

    def restart_faults(self, Ms: tuple[np.ndarray, ...], Ps: tuple[np.ndarray, ...]) -> None:
        """Every fault filter from the healthy filter's estimate (in place): its shared states'
        mean and covariance, and its parameters back at their prior (the given values, the
        prior covariance, no correlation with the states).

        Why: the filters start at the steady state of the nominal inputs, and a plant run at
        other set points (the closed-loop study's) is far from it; over that start-up a fault
        filter's free parameter absorbs the offset (f1's ρ_b did, for 400-1600 samples), and a
        posterior that forgets slowly keeps that belief. Restarting the fault filters from the
        healthy one once it has converged leaves them only the innovations after it."""
        n0 = Ms[0].shape[0]
        for h in range(1, len(Ms)):
            m0, P0 = self.estimators[h].initial_prior(1)
            Ms[h][:n0] = Ms[0]
            Ms[h][n0:] = m0[0, n0:]
            Ps[h][...] = 0.0
            Ps[h][:n0, :n0] = Ps[0]
            Ps[h][n0:, n0:] = P0[0, n0:, n0:]

    def run(
        self, Ms: tuple[np.ndarray, ...], Ps: tuple[np.ndarray, ...], Y: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Filter ``Y`` (T, n_obs) from the priors ``Ms``, ``Ps`` (advanced in place):
        ``(whitened (T, H, 8), log-likelihoods (T, H))``."""
        Y = np.ascontiguousarray(Y, dtype=np.float64)
        first = self.estimators[0].filter_model
        H, T = len(self.estimators), Y.shape[0]
        white = np.empty((T, H, first.r_abs.shape[0]))
        loglik = np.empty((T, H))
        cfg = self.estimators[0].config
        gate = math.inf if cfg.step_gate is None else float(cfg.step_gate)
        bank_run(
            self.models,
            Ms,
            Ps,
            Y,
            self.qs,
            self.weights,
            first.r_abs,
            first.r_rel,
            first.gate_idx,
            first.gate_lin,
            gate,
            max(e.filter_model.n_scratch for e in self.estimators),
            white,
            loglik,
        )
        return white, loglik


def calibrate_walks(
    params: FCCParams,
    config: UKFConfig,
    faults: tuple[str, ...],
    Y: np.ndarray,
    *,
    rate: float,
    initial_std_rel: float,
    probe_walk: float = 1e-3,
    settle: int = 300,
) -> tuple[float, ...]:
    """Each fault's parameter walk ``rate / √I``, with ``I`` the information one healthy sample
    holds about the fault's relative size, read from a probe filter on ``Y`` (T, n_obs).

    Why: an equal relative walk for every fault made the filters of sensitive parameters (ρ_b,
    the reactor holdup) pay far more for their freedom on healthy data than the weir constants'
    (an Occam cost 10 times larger per sample), so a small f1 was given to f2. For a random
    walk of std σ observed with information I per sample, the steady posterior variance is
    ``P ≈ σ / √I``: the probe (walk ``probe_walk``) gives ``I = σ² / P²``, and a walk
    ``σ = rate / √I`` gives every fault the same tracking time (``1 / rate`` samples) and the
    same cost on healthy data (about ``rate / 2`` nats per sample). A fault with several
    parameters takes the geometric mean of their walks.
    """
    Y = np.asarray(Y, dtype=np.float64)
    if Y.ndim != 2 or Y.shape[0] <= settle + 10:
        raise invalid("Y", f"shape {Y.shape}", f"(T > {settle + 10}, channels) observations")
    walks = []
    for f in faults:
        fields = fault_definition(f).parameters
        cfg = config.replace(
            parameters=fields,
            parameter_walk_std_rel=probe_walk,
            parameter_initial_std_rel=initial_std_rel,
        )
        est = FCCStateEstimator(params, cfg)
        out = est.filter(Y[None], innovation_cov=False)
        logs = []
        for name in fields:
            rel = out.state_std[0, settle:, est.state_names.index(name)] / abs(
                getattr(params, name)
            )
            P = float(np.mean(rel**2))
            info = probe_walk**2 / P**2
            logs.append(math.log(min(rate / math.sqrt(info), 0.1)))
        walks.append(math.exp(float(np.mean(logs))))
    return tuple(walks)
