"""The algebra of ``valve-glr``: the windowed GLRs of a valve that stopped following its command.

A quasi-steady loop (the riser outlet follows the catalyst flow within a sample) gives a
residual ``r_t = y_t − ŷ(command_t, …)`` that reads ``gain · (position_t − command_t)``: zero
while the valve follows its command, whatever the loop does. A valve that sticks after sample
``k0`` holds ``position = command_k0``, so after it

    r_t − r̄  =  −a · gain · (command_t − command_k0) + noise,        a = 1

(``a`` < 1: a valve that still passes part of each move, ``valve-stuck`` with m = a); a valve
that passes a constant extra flow shifts ``r`` by a step. For every onset ``k0`` in a window,
the reference ``r̄`` is the residual's mean over the ``reference`` samples up to ``k0``
(it absorbs the model's slow error), and the two log-likelihood ratios, the noise white with
std ``sigma``, are

* **stuck**: ``max over a in [a_min, 1] of Σ (a z φ − a² φ² / 2) / σ²`` with ``z = r − r̄``,
  ``φ = −gain (command − command_k0)``: the size bounded below so that a model gain a few
  per cent off, which a large command move (a set-point step) turns into a residual
  proportional to ``φ``, fits ``a`` near 0 and is not taken for a sticking valve;
* **bias**: ``(Σ z)² / (2 σ² n (1 + n / reference))``: a step of unknown size (the reference
  mean's own noise in the variance), :func:`step_glr`.

:func:`onset_statistics` computes both over one buffer (oldest first, the current sample
last) from suffix sums, O(window) a sample. A valve bias is a step the loop then hides from
the controlled variable but not from ``r`` (the command moves by the bias, the position does
not): the step stays, while the window slides past its onset. :func:`step_glr` on the latest
samples against the reference mean kept from the onset the windowed test found is the same
GLR with the onset held (``valve-glr``'s ``hold``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["OnsetStatistics", "onset_statistics", "step_glr"]


class OnsetStatistics(NamedTuple):
    """The largest of each GLR over the onsets, and where the stuck one is largest."""

    stuck: float  #: the stuck valve's log-likelihood ratio
    bias: float  #: the step's
    size: float  #: the stuck GLR's fitted share of the moves lost, ``a`` (0: none)
    since: int  #: samples since its onset (0: none)
    bias_since: int = 0  #: samples since the bias GLR's best onset (0: none)
    bias_reference: float = 0.0  #: the reference mean ``r̄`` at that onset


def step_glr(
    sum_z: np.ndarray | float, n: np.ndarray | float, *, sigma: float, reference: int
) -> np.ndarray | float:
    """The step's GLR ``(Σ z)² / (2 σ² n (1 + n / reference))`` of ``n`` samples whose
    deviations from a ``reference``-sample mean sum to ``sum_z`` (white noise of std
    ``sigma``; the reference mean's own variance ``σ² / reference`` is in the denominator).

    >>> round(step_glr(3.0, 10, sigma=0.2, reference=20), 2)
    7.5
    """
    return sum_z * sum_z / (2.0 * sigma * sigma * n * (1.0 + n / reference))


def onset_statistics(
    r: np.ndarray,
    command: np.ndarray,
    *,
    gain: float,
    sigma: float,
    reference: int,
    a_min: float,
) -> OnsetStatistics:
    """The two GLRs (module docstring) over the buffer ``r``, ``command`` ``(n,)``, the current
    sample last, maximised over the onsets that leave ``reference`` samples before them and at
    least one after; zeros while the buffer holds fewer than ``reference + 1``.

    >>> u = np.r_[np.zeros(20), np.arange(1.0, 11.0)]  # the command ramps after sample 19
    >>> stuck = onset_statistics(-u, u, gain=1.0, sigma=1.0, reference=10, a_min=0.5)
    >>> round(stuck.stuck, 1), stuck.since, stuck.size
    (192.5, 10, 1.0)
    >>> onset_statistics(0 * u, u, gain=1.0, sigma=1.0, reference=10, a_min=0.5).stuck
    0.0
    """
    n_all = r.shape[0]
    if n_all < reference + 1:
        return OnsetStatistics(0.0, 0.0, 0.0, 0)
    u = command - command[-1]  # small numbers: the sums below subtract
    # suffix sums from each index: S[j] = Σ_{τ ≥ j}
    s_r = np.cumsum(r[::-1])[::-1]
    s_u = np.cumsum(u[::-1])[::-1]
    s_ru = np.cumsum((r * u)[::-1])[::-1]
    s_uu = np.cumsum((u * u)[::-1])[::-1]
    j = np.arange(reference - 1, n_all - 1)  # the last sample before the onset
    n = (n_all - 1 - j).astype(np.float64)  # samples after it
    c_r = np.concatenate(([0.0], np.cumsum(r)))
    mean = (c_r[j + 1] - c_r[j + 1 - reference]) / reference  # r̄ over the reference samples
    uj = u[j]
    a_r, a_u, a_ru, a_uu = s_r[j + 1], s_u[j + 1], s_ru[j + 1], s_uu[j + 1]
    # Σ z φ and Σ φ² over the samples after j, φ = −gain (u − u_j), z = r − r̄
    s_zphi = -gain * (a_ru - uj * a_r - mean * a_u + n * mean * uj)
    s_phi2 = gain * gain * np.maximum(a_uu - 2.0 * uj * a_u + n * uj * uj, 0.0)
    var = sigma * sigma
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.clip(np.where(s_phi2 > 0.0, s_zphi / s_phi2, 0.0), a_min, 1.0)
    stuck = np.maximum(a * s_zphi - 0.5 * a * a * s_phi2, 0.0) / var
    bias = step_glr(a_r - n * mean, n, sigma=sigma, reference=reference)
    step = int(np.argmax(bias))
    held = (int(n[step]), float(mean[step]))
    best = stuck.shape[0] - 1 - int(np.argmax(stuck[::-1]))  # ties: the latest onset
    if stuck[best] <= 0.0:
        return OnsetStatistics(0.0, float(bias[step]), 0.0, 0, *held)
    return OnsetStatistics(
        float(stuck[best]), float(bias[step]), float(a[best]), int(n[best]), *held
    )
