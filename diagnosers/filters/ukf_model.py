"""The FCC model as the filter sees it: the augmented state, its coordinates, the compiled
transition and measurement (:func:`fcc_transition`, :func:`fcc_measure`) and the noise model.

The augmented state, in order:

* the 11 model states (:data:`fcc_env.STATE_NAMES`);
* the true R_ar, T_ar, T_fp held over the sample (random walks with steps): the readings of
  Table 1's first three channels measure them, so the filter never takes a noisy reading for
  the input itself;
* f_coke (with ``estimate_coking``): the feed coking factor, a random walk;
* the parameters named in ``parameters`` (random walks around the given values);
* per channel of ``sensor_lags``, the lag's coefficient (a random walk), then, last, the
  lagged readings themselves: ``y_c = a·L_c + (1 − a)·T_c(x_k)``, ``L_c ← y_c`` (the plant's
  exact discretisation of a first-order lag, :mod:`fcc_env.effects`' ``sensor_lag``).

The filter works in scaled coordinates ``z_s = (z − ref) / scale`` (:data:`STATE_SCALES`:
°C, t/h, 10³ kg, 10⁻⁵ kg/kg, 0.01 for f_coke, 1 % of a parameter's value), so the covariance
is well conditioned whatever the units; the model functions map each sigma point back.
One sample advances the model states by the plant's own RK4 step
(:func:`fcc_env.integrator.step_kernel`) and measures them with the plant's own measurement map
(:func:`fcc_env.physics.measure_core`), so on the exact parameters the model is the plant.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from diagnosers.filters.ukf_config import UKFConfig
from diagnosers.filters.ukf_kernels import (
    STATUS_SKIPPED,
    posterior,
    predict_finish,
    predict_prepare,
    skip_outputs,
    update_finish,
    update_prepare,
    workspace,
)
from fcc_env.integrator import NO_FAULT, step_kernel
from fcc_env.params import (
    INPUT_NAMES,
    MEASUREMENT_NAMES,
    N_MEASUREMENTS,
    N_STATES,
    NOMINAL_INPUTS,
    PARAM_INDEX,
    STATE_NAMES,
    FCCParams,
)
from fcc_env.physics import measure_core, njit_kernel, steady_state
from fcc_env.plant import NOISE_STD_ABS, NOISE_STD_REL

__all__ = [
    "ESTIMATED_INPUTS",
    "STATE_SCALES",
    "FCCFilterModel",
    "fcc_filter_batch",
    "fcc_filter_streams",
    "fcc_measure",
    "fcc_sample",
    "fcc_transition",
    "work_vectors",
]

#: The inputs estimated behind their readings (Table 1's channels 0-2 read them).
ESTIMATED_INPUTS: tuple[str, ...] = ("R_ar", "T_ar", "T_fp")
_INPUT_COLUMNS = tuple(INPUT_NAMES.index(n) for n in ESTIMATED_INPUTS)
_COKE_COLUMN = INPUT_NAMES.index("f_coke")
#: Filter units of the 11 model states: 10³ kg, 10⁻⁵ kg/kg (0.001 wt%), °C.
STATE_SCALES: tuple[float, ...] = (1e3, 1e-5, 1e3, 1e-5, 1.0, 1e3, 1e-5, 1.0, 1e3, 1.0, 1.0)
_COKE_SCALE = 0.01
_PARAMETER_SCALE_REL = 0.01
#: Filter unit of a lag coefficient (dimensionless, in [0, 0.95]).
_LAG_COEF_SCALE = 0.1
#: The largest lag coefficient the model applies (a 195 s lag at 10 s samples): a sigma point
#: beyond it would make the reading a near-constant.
_LAG_COEF_MAX = 0.95
#: Where the closed-loop observation carries the valve command (fcc_env.CLOSED_LOOP_CHANNELS).
_VALVE_CHANNEL = N_MEASUREMENTS
_NO_MULT = np.ones(NO_FAULT.shape[0])
# ints layout of the model tuple
_I_COKE, _I_SUBSTEPS, _I_CLOSED = 0, 1, 2


@njit_kernel
def _physical(z, obs, model, x, u, p) -> None:
    """The plant's state ``x``, inputs ``u`` and the estimated parameters in ``p`` at filter
    point ``z`` (``p``'s other entries are the given parameters, :func:`work_vectors`)."""
    scale, ref, _, u_nom, pslot, pindex, ints, _, _ = model
    for i in range(x.shape[0]):
        x[i] = ref[i] + scale[i] * z[i]
    for i in range(u.shape[0]):
        u[i] = u_nom[i]
    if ints[_I_CLOSED] != 0:
        u[0] = obs[_VALVE_CHANNEL]
    for j in range(len(_INPUT_COLUMNS)):
        s = N_STATES + j
        u[_INPUT_COLUMNS[j]] = ref[s] + scale[s] * z[s]
    c = ints[_I_COKE]
    if c >= 0:
        u[_COKE_COLUMN] = ref[c] + scale[c] * z[c]
    for j in range(pslot.shape[0]):
        s = pslot[j]
        p[pindex[j]] = ref[s] + scale[s] * z[s]


@njit_kernel
def _lagged(z, model, j, value):
    """The ``j``-th lagged channel's reading at filter point ``z`` when the true value is
    ``value``: ``a·L + (1 − a)·value``, ``a`` the lag's coefficient clipped to [0, max]."""
    scale, ref, lags = model[0], model[1], model[8]
    c, s_l = lags[j, 0], z.shape[0] - lags.shape[0] + j
    a = min(max(ref[c] + scale[c] * z[c], 0.0), _LAG_COEF_MAX)
    return a * (ref[s_l] + scale[s_l] * z[s_l]) + (1.0 - a) * value


@njit_kernel
def work_vectors(model, scratch):
    """Views of ``scratch``: the plant's state, inputs and parameters at a filter point, the
    parameters set to the given ones (the sigma points change only the estimated ones)."""
    p_base = model[2]
    x = scratch[:N_STATES]
    u = scratch[N_STATES : N_STATES + 6]
    p = scratch[N_STATES + 6 : N_STATES + 6 + p_base.shape[0]]
    for i in range(p_base.shape[0]):
        p[i] = p_base[i]
    return x, u, p


@njit_kernel
def fcc_transition(z, obs, model, x, u, p, out) -> None:
    """The filter point of the next sample: one RK4 sample of the model states under the
    inputs held over this one; the random walks' states unchanged (their noise is ``Q``).
    ``x``, ``u``, ``p`` are work vectors, ``p`` holding the given parameters
    (:func:`work_vectors`)."""
    scale, ref, _, _, _, _, ints, reals, lags = model
    _physical(z, obs, model, x, u, p)
    n_walk = z.shape[0] - lags.shape[0]  # the lagged readings come last
    if lags.shape[0]:  # each lagged reading takes this sample's value (out[:8] as scratch)
        measure_core(x, u, p, out[:N_MEASUREMENTS])
        for j in range(lags.shape[0]):
            s_l, ch = n_walk + j, lags[j, 1]
            out[s_l] = (_lagged(z, model, j, out[ch]) - ref[s_l]) / scale[s_l]
    step_kernel(x, u, p, NO_FAULT, _NO_MULT, reals[0], ints[_I_SUBSTEPS])
    for i in range(N_STATES):
        out[i] = (x[i] - ref[i]) / scale[i]
    for i in range(N_STATES, n_walk):
        out[i] = z[i]


@njit_kernel
def fcc_measure(z, obs, model, x, u, p, out) -> None:
    """Table 1's noise-free measurements at filter point ``z`` (the plant's measurement map:
    the true inputs, T_rx from the riser, the four temperature states); work vectors as for
    :func:`fcc_transition`."""
    _physical(z, obs, model, x, u, p)
    measure_core(x, u, p, out)
    lags = model[8]
    for j in range(lags.shape[0]):
        out[lags[j, 1]] = _lagged(z, model, j, out[lags[j, 1]])


@njit_kernel
def fcc_sample(model, m, P, y, fixed, ws, out) -> int:
    """One sample of one episode (:mod:`diagnosers.filters.ukf_kernels`' order): ``m``, ``P``
    go from this sample's prior to the next one's; returns the status bits.

    ``fixed``: ``(q, r_abs, r_rel, gate_idx, gate_lin, gate, w)``, what stays the same from
    sample to sample; ``out``: ``(innov, stdz, white, S, post, post_sd, jumps)``, this
    sample's outputs (one tuple each, so that every caller, the bank of hypotheses
    :func:`diagnosers.isolation.filter_bank.bank_run` too, passes the same two names)."""
    q, r_abs, r_rel, gate_idx, gate_lin, gate, w = fixed
    innov, stdz, white, S, post, post_sd, jumps = out
    X, FX, HY = ws[1], ws[2], ws[3]
    x, u, p = work_vectors(model, ws[9])
    status = update_prepare(m, P, y, r_abs, r_rel, gate_idx, gate_lin, gate, w, ws, jumps)
    if status & STATUS_SKIPPED:
        skip_outputs(innov, stdz, white, S)
    else:
        for i in range(X.shape[0]):
            fcc_measure(X[i], y, model, x, u, p, HY[i])
        status |= update_finish(m, P, y, w, ws, innov, stdz, white, S)
    posterior(m, P, post, post_sd)
    status |= predict_prepare(m, P, w, ws)
    for i in range(X.shape[0]):
        fcc_transition(X[i], y, model, x, u, p, FX[i])
    predict_finish(m, P, q, w, ws)
    return status


@numba.njit(cache=True, nogil=True, parallel=True, error_model="numpy")
def fcc_filter_batch(
    model,
    M,
    P,
    Y,
    q,
    r_abs,
    r_rel,
    gate_idx,
    gate_lin,
    gate,
    w,
    n_scratch,
    INNOV,
    STDZ,
    WHITE,
    S,
    POST,
    POST_SD,
    JUMPS,
    STATUS,
) -> None:
    """Every sample of B episodes ``Y`` (B, T, n_obs), episodes in parallel threads; ``M``
    (B, n), ``P`` (B, n, n) start at the priors and end at the priors after the last sample.
    Outputs (B, T, ...) as :func:`fcc_sample`'s; ``S`` may be (B, 1, n_y, n_y), where each
    sample's innovation covariance overwrites the last (kept only for the whitening)."""
    n, ny = M.shape[1], r_abs.shape[0]
    keep_s = S.shape[1] == Y.shape[1]
    fixed = (q, r_abs, r_rel, gate_idx, gate_lin, gate, w)
    for b in numba.prange(Y.shape[0]):
        ws = workspace(n, ny, n_scratch)
        for k in range(Y.shape[1]):
            out = (
                INNOV[b, k],
                STDZ[b, k],
                WHITE[b, k],
                S[b, k if keep_s else 0],
                POST[b, k],
                POST_SD[b, k],
                JUMPS[b, k],
            )
            STATUS[b, k] = fcc_sample(model, M[b], P[b], Y[b, k], fixed, ws, out)


@njit_kernel
def fcc_filter_streams(
    model,
    M,
    P,
    Y,
    q,
    r_abs,
    r_rel,
    gate_idx,
    gate_lin,
    gate,
    w,
    n_scratch,
    INNOV,
    STDZ,
    WHITE,
    S,
    POST,
    POST_SD,
    JUMPS,
    STATUS,
) -> None:
    """One sample ``Y`` (B, n_obs) of B streams, in one thread (a parallel region per sample
    costs more than it saves: its threads' barrier, on a busy machine, milliseconds)."""
    n, ny = M.shape[1], r_abs.shape[0]
    ws = workspace(n, ny, n_scratch)
    fixed = (q, r_abs, r_rel, gate_idx, gate_lin, gate, w)
    for b in range(Y.shape[0]):
        out = (INNOV[b], STDZ[b], WHITE[b], S[b], POST[b], POST_SD[b], JUMPS[b])
        STATUS[b] = fcc_sample(model, M[b], P[b], Y[b], fixed, ws, out)


@dataclass(frozen=True)
class FCCFilterModel:
    """Everything the compiled filter needs of the FCC model for one ``(params, config)``."""

    names: tuple[str, ...]  # augmented state names
    scale: np.ndarray  # (n,) filter units
    ref: np.ndarray  # (n,) the prior mean, physical
    model: tuple  # the tuple fcc_transition and fcc_measure read
    q: np.ndarray  # (n,) process-noise variances per sample, filter units
    p0: np.ndarray  # (n,) prior variances, filter units
    r_abs: np.ndarray  # (8,) measurement-noise std, absolute
    r_rel: np.ndarray  # (8,) relative to the reading
    gate_idx: np.ndarray  # (3, 2) (state, channel) of the directly read inputs
    gate_lin: np.ndarray  # (3, 3) offset, gain, step variance
    n_scratch: int

    @property
    def n(self) -> int:
        return len(self.names)

    @classmethod
    def build(cls, params: FCCParams, config: UKFConfig) -> FCCFilterModel:
        """The model of ``params`` (the filter's own argument, never a plant's) and ``config``."""
        config.check_parameters(params)
        p_base = params.as_array()
        x0 = steady_state(params, NOMINAL_INPUTS)
        u_read = NOMINAL_INPUTS[list(_INPUT_COLUMNS)]
        names = [*STATE_NAMES, *ESTIMATED_INPUTS]
        scale = [*STATE_SCALES, 1.0, 1.0, 1.0]
        ref = [*x0, *u_read]
        st = config.state_noise_std
        read_sd = config.noise_scale * (NOISE_STD_ABS[:3] + NOISE_STD_REL[:3] * u_read)
        walk = (config.air_walk * u_read[0], config.input_walk_std_C, config.input_walk_std_C)
        q = [st * st] * N_STATES + [w * w for w in walk]
        p0 = [config.initial_state_std**2] * N_STATES + list(read_sd**2)
        coke = -1
        if config.coking:
            coke = len(names)
            names.append("f_coke")
            scale.append(_COKE_SCALE)
            ref.append(float(NOMINAL_INPUTS[_COKE_COLUMN]))
            q.append((config.coking_walk_std / _COKE_SCALE) ** 2)
            p0.append((config.coking_initial_std / _COKE_SCALE) ** 2)
        pslot, pindex = [], []
        rel = config.parameter_walk_std_rel / _PARAMETER_SCALE_REL
        rel0 = config.parameter_initial_std_rel / _PARAMETER_SCALE_REL
        for name in config.parameters:
            pslot.append(len(names))
            pindex.append(PARAM_INDEX[name])
            names.append(name)
            value = float(getattr(params, name))
            scale.append(_PARAMETER_SCALE_REL * abs(value))
            ref.append(value)
            q.append(rel * rel)
            p0.append(rel0 * rel0)
        lag_rows = []
        if config.sensor_lags:
            y0 = np.empty(N_MEASUREMENTS)
            measure_core(x0, NOMINAL_INPUTS.copy(), p_base, y0)
            for ch_name in config.sensor_lags:  # the coefficients
                lag_rows.append([len(names), MEASUREMENT_NAMES.index(ch_name)])
                names.append(f"lag_coef[{ch_name}]")
                scale.append(_LAG_COEF_SCALE)
                ref.append(config.lag_coefficient_prior)
                q.append((config.lag_walk_std / _LAG_COEF_SCALE) ** 2)
                p0.append((config.lag_coefficient_std / _LAG_COEF_SCALE) ** 2)
            for ch_name in config.sensor_lags:  # the lagged readings, last
                names.append(f"lag[{ch_name}]")
                scale.append(1.0)
                ref.append(float(y0[MEASUREMENT_NAMES.index(ch_name)]))
                q.append(st * st)
                p0.append(config.initial_state_std**2)
        lag_arr = np.array(lag_rows, dtype=np.int64).reshape(-1, 2)
        scale_a, ref_a = np.array(scale), np.array(ref)
        ints = np.array([coke, config.rk4_substeps, int(config.closed_loop)], dtype=np.int64)
        reals = np.array([config.sample_time_s / config.rk4_substeps])
        model = (
            scale_a,
            ref_a,
            p_base,
            NOMINAL_INPUTS.copy(),
            np.array(pslot, dtype=np.int64),
            np.array(pindex, dtype=np.int64),
            ints,
            reals,
            lag_arr,
        )
        steps = (config.air_step_std_rel * u_read[0], config.step_std_C, config.step_std_C)
        reads = [MEASUREMENT_NAMES.index(name) for name in ESTIMATED_INPUTS]  # their channels
        gate_idx = np.array([[N_STATES + j, ch] for j, ch in enumerate(reads)], dtype=np.int64)
        gate_lin = np.array([[ref_a[N_STATES + j], 1.0, steps[j] ** 2] for j in range(3)])
        return cls(
            names=tuple(names),
            scale=scale_a,
            ref=ref_a,
            model=model,
            q=np.maximum(np.array(q), 1e-300),  # a zero variance would stall the Cholesky
            p0=np.maximum(np.array(p0), 1e-300),
            r_abs=config.noise_scale * NOISE_STD_ABS,
            r_rel=config.noise_scale * NOISE_STD_REL,
            gate_idx=gate_idx,
            gate_lin=gate_lin,
            n_scratch=N_STATES + 6 + p_base.shape[0],
        )

    @property
    def channels(self) -> tuple[str, ...]:
        """The measured channels whose innovations the filter reports (Table 1)."""
        return MEASUREMENT_NAMES
