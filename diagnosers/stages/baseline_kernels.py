"""Compiled per-sample steps of :class:`diagnosers.stages.baseline.RegressionBaseline` and
:class:`diagnosers.stages.baseline.HeldBaseline`: the streaming path runs once per sample, where the
NumPy calls' own overhead (not their arithmetic: k ≈ 3 systems of p ≈ 13) was a third of
``lrgf-glr-adaptive``'s ``update``.

Every kernel does the same floating-point operations in the same order as the NumPy code it
replaces (element-wise, no reassociation, no fused multiply-add), so results stay identical bit
for bit. The solve is the one exception to "same operations": a compiled LU would round
differently from LAPACK, so :func:`adapt_step` calls the very ``dgesv`` that
``numpy.linalg.solve`` calls, from NumPy's own LAPACK library. When that routine cannot be
found or does not reproduce ``numpy.linalg.solve`` on a probe system (:func:`solver` is None),
:func:`adapt_step` solves with NumPy.
"""

from __future__ import annotations

import ctypes
import functools
import importlib
from collections.abc import Callable

import numba
import numpy as np

__all__ = ["adapt_step", "filter_step", "information_step", "signals_step", "solver"]

#: ``dgesv`` symbol names with 64-bit integers (NumPy's ILP64 OpenBLAS builds), most likely first
_DGESV_NAMES = ("scipy_dgesv_64_", "dgesv_64_", "dgesv_64")


@numba.njit(cache=True, nogil=True, error_model="numpy")
def signals_step(
    y: np.ndarray,
    y_m: np.ndarray,
    gather: np.ndarray,
    mean: np.ndarray,
    scale: np.ndarray,
    out: np.ndarray,
) -> None:
    """``out = (ext[gather] − mean) / scale`` with ``ext = [y, y_m, 0]`` (``gather`` indexes
    ``ext``: ``len(y)`` is the first model output, ``len(y) + len(y_m)`` the padding's 0)."""
    n_y, n_m = y.shape[0], y_m.shape[0]
    for j in range(gather.shape[0]):
        for w in range(gather.shape[1]):
            g = gather[j, w]
            v = y[g] if g < n_y else (y_m[g - n_y] if g < n_y + n_m else 0.0)
            out[j, w] = (v - mean[j, w]) / scale[j, w]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def filter_step(x: np.ndarray, gains: np.ndarray, state: np.ndarray, started: bool) -> None:
    """One sample ``x`` ``(k, width)`` into the low-pass states ``(k, n_taus, width)``: set to
    ``x`` at the first sample, else ``s ← s + a (x − s)``."""
    for j in range(state.shape[0]):
        for i in range(state.shape[1]):
            a = gains[i]
            for w in range(state.shape[2]):
                if started:
                    s = state[j, i, w]
                    state[j, i, w] = s + a * (x[j, w] - s)
                else:
                    state[j, i, w] = x[j, w]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def information_step(
    info: np.ndarray,
    moment: np.ndarray,
    phi: np.ndarray,
    e: np.ndarray,
    forgetting: float,
    prior: np.ndarray,
) -> None:
    """``R ← f R + (φ φᵀ + P)`` and ``b ← f b + φ e`` of every relation, in place."""
    for j in range(info.shape[0]):
        for r in range(info.shape[1]):
            for c in range(info.shape[2]):
                info[j, r, c] = info[j, r, c] * forgetting + (phi[j, r] * phi[j, c] + prior[r, c])
            moment[j, r] = moment[j, r] * forgetting + phi[j, r] * e[j]


def _numpy_dgesv() -> int | None:
    """The address of the ``dgesv`` NumPy's ``linalg`` module links to, or None."""
    umath = importlib.import_module("numpy.linalg._umath_linalg")
    try:
        lib = ctypes.CDLL(umath.__file__)  # dlsym on it also searches its LAPACK dependency
    except OSError:
        return None
    for name in _DGESV_NAMES:
        fn = getattr(lib, name, None)
        if fn is not None:
            return ctypes.cast(fn, ctypes.c_void_p).value
    return None


def _make_adapt(address: int) -> Callable[..., None]:
    dgesv = ctypes.CFUNCTYPE(None, *[ctypes.c_void_p] * 8)(address)

    # not cached: the routine's address is a constant of this process
    @numba.njit(nogil=True, error_model="numpy")
    def adapt(
        info: np.ndarray,
        moment: np.ndarray,
        theta: np.ndarray,
        phi: np.ndarray,
        e: np.ndarray,
        forgetting: float,
        prior: np.ndarray,
    ) -> None:
        information_step(info, moment, phi, e, forgetting, prior)
        p = info.shape[1]
        dims = np.array([p, 1, p, p, 0], dtype=np.int64)  # N, NRHS, LDA, LDB, INFO
        a = np.empty((p, p))
        piv = np.empty(p, dtype=np.int64)
        for j in range(info.shape[0]):
            # R is symmetric bit for bit (products commute), so C order is its Fortran order
            a[:, :] = info[j]
            theta[j, :] = moment[j]
            dgesv(
                dims[0:].ctypes,
                dims[1:].ctypes,
                a.ctypes,
                dims[2:].ctypes,
                piv.ctypes,
                theta[j].ctypes,
                dims[3:].ctypes,
                dims[4:].ctypes,
            )

    return adapt


def _probe(adapt: Callable[..., None]) -> bool:
    """Whether ``adapt`` gives ``numpy.linalg.solve``'s bits on a few random systems."""
    rng = np.random.default_rng(0)
    k, p = 3, 13
    info = np.broadcast_to(np.eye(p), (k, p, p)).copy()
    moment, theta = np.zeros((k, p)), np.zeros((k, p))
    prior = 0.01 * np.eye(p)
    for _ in range(20):
        phi, e = rng.normal(size=(k, p)), rng.normal(size=k)
        adapt(info, moment, theta, phi, e, 0.9, prior)
        if not np.array_equal(theta, np.linalg.solve(info, moment[:, :, None])[:, :, 0]):
            return False
    return True


@functools.cache
def solver() -> Callable[..., None] | None:
    """``adapt(info, moment, theta, phi, e, forgetting, prior)``: the information update and the
    solve ``θ = R⁻¹ b`` of every relation in place, with NumPy's ``dgesv``; None when that
    routine cannot be found or does not reproduce ``numpy.linalg.solve`` on a probe. Compiled
    at the first call (a second or so), not at import."""
    address = _numpy_dgesv()
    if address is None:
        return None
    adapt = _make_adapt(address)
    try:
        return adapt if _probe(adapt) else None
    except Exception:  # a routine of another signature: use NumPy
        return None


def adapt_step(
    info: np.ndarray,
    moment: np.ndarray,
    theta: np.ndarray,
    phi: np.ndarray,
    e: np.ndarray,
    forgetting: float,
    prior: np.ndarray,
) -> None:
    """The information update and ``θ = R⁻¹ b`` of every relation, in place."""
    adapt = solver()
    if adapt is not None:
        adapt(info, moment, theta, phi, e, forgetting, prior)
        return
    information_step(info, moment, phi, e, forgetting, prior)
    theta[...] = np.linalg.solve(info, moment[:, :, None])[:, :, 0]
