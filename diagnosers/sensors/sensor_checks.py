"""The per-sample decisions of ``sensor-validation``: three checks per sensor and the rule that
names the faulty sensor and the kind of its fault.

Three checks, each a normalised statistic with its limit at 1 (:func:`decide_run`):

* **model consistency** (the generalised observer scheme of :mod:`diagnosers.sensors.loo_bank`):
  per filter ``h``, the EWMA ``a_h`` (rate ``lam``) of its whitened innovations and
  ``M_h = |a_h|² (2 − lam) / lam`` (χ² with as many degrees of freedom as channels it reads
  while its model is right), over its limit learned on healthy training records. Filter 0
  (every sensor) alarms; the sensor whose leave-out filter stays the most consistent,
  ``argmin_h M_h / limit_h``, is the faulty one;
* **noise level**: per channel, the EWMA of ``min(|Δy|, clip)`` (sample-to-sample change,
  clipped at ``clip`` so that one step of the process or a bias counts little) over its
  healthy limit. A transmitter's noise shows in its own differences first; why not the
  model's innovation: the filter declares a step of an input read directly (T_ar, T_fp,
  R_ar) when its reading jumps, and so swallows the noise of exactly those channels;
* **held values**: a decaying count (rate ``hold_decay``) of samples that repeat the channel's
  last reading bit for bit, over ``HOLD_COUNT``. A noisy reading repeats itself about once
  in 4000 samples (float32 observations); a stuck or dropped-out transmitter does at once
  (the env holds the last value, as a DCS does, and never gives NaN).

**Which sensor** (no hold, no noise): among the leave-out filters, the one that is consistent
and whose left-out sensor disagrees most with its prediction: the largest
``z_c / max(L_{c+1}, CONSISTENT)``, ``z_c`` the EWMA of sensor ``c``'s dedicated residual
over its healthy limit and ``L_h`` filter h's *slow* consistency: ``M_h`` of an EWMA at rate
``lam_iso`` (default 0.001: a memory of about 1000 samples) of its whitened innovations on the
seven channels it reads, over its healthy limit. Why not the least inconsistent filter alone:
leaving out an input read directly (T_fp) lets that filter explain an offset of another sensor
(T_rx) by a change of the unread input, so two filters stay consistent; the dedicated residual
tells them apart. Why slow: the wrong one of such a pair is told by the process's slow answer
(a T_fp bias read as a T_rx bias implies a hotter riser, which the regenerator shows over
minutes), which a 50-sample EWMA (``lam``) forgets faster than it grows, and the T_fp-less
filter, whose healthy limit its lag after each programmed T_fp step sets ~50× the others',
was floored at 0.01 and so won against any filter merely as consistent
(``lab/sensor-validation.md``, 2026-12-07).

Where another test names the sensor (``NAMED`` ≥ 0: the GLR bank of bias hypotheses of
:mod:`diagnosers.sensors.glr_bank` over an alarm's first samples), that one is taken instead,
and the kind it says (``NAMED_KIND`` > 0: a bias or a drift) too.

**Kind**, for the sensor named: held values with a break in the holding (a fresh sample
between held ones, decaying count ``> 0.5``) are a dropout, an unbroken hold stuck; a noise
check over its limit is noise; otherwise the dedicated residual since the alarm began decides
between a bias and a drift: a drift once its least-squares slope's t statistic passes
``t_drift`` (the sign of its level) and the growth it fits since the alarm is over half the
level (a bias's residual wanders slowly with the model's error, and over thousands of samples
any slow wander's slope is "significant"); else a bias once ``settle`` samples passed without a
slope; before that, a bias if the residual's mean since the alarm is ``step_ratio`` times its
slow EWMA (rate 0.01) just before the alarm (a step: nothing before it), else a drift (a ramp
was already growing before it crossed a limit).
"""

from __future__ import annotations

import math

import numpy as np

from fcc_env.physics import njit_kernel

__all__ = ["CONSISTENT", "HOLD_COUNT", "KINDS", "decide_run", "new_state"]

#: The kinds of sensor fault the rule names, in the order of its codes 1..5.
KINDS: tuple[str, ...] = (
    "sensor-bias",
    "sensor-drift",
    "sensor-stuck",
    "sensor-noise",
    "sensor-dropout",
)
#: Held samples (decaying count) that make a hold: two repeats close together.
HOLD_COUNT = 1.5
#: The slow consistency (over its healthy maximum) under which every leave-out filter counts as
#: equally consistent: a tenth of that maximum (0.1 against 0.01, 0.3 and 1 on training seeds
#: 1100-1101, lab/sensor-validation.md).
CONSISTENT = 0.1
_BIAS, _DRIFT, _STUCK, _NOISE, _DROPOUT = 1, 2, 3, 4, 5


def new_state(n_filters: int, n_channels: int) -> dict[str, np.ndarray]:
    """A fresh state of :func:`decide_run` (an episode's start)."""
    H, C = n_filters, n_channels
    return {
        "count": np.zeros(1),  # samples seen; alarmed flag of the last sample
        "ewma": np.zeros((H, C)),
        "slow": np.zeros((H, C)),  # EWMA (rate lam_iso) of the innovations a filter reads
        "prev": np.full(C, np.nan),
        "diff": np.zeros(C),
        "held": np.zeros(C),
        "breaks": np.zeros(C),
        "last_held": np.zeros(C),
        "reg": np.zeros((C, 5)),  # since the alarm began: n, Σe, Σe², Σ j·e (j from 0), spare
        "regj": np.zeros((C, 2)),  # Σj, Σj²
        "alarmed": np.zeros(1),
        "ded_fast": np.zeros(C),  # EWMA (rate lam) of the dedicated residuals
        "ded_slow": np.zeros(C),  # EWMA (rate 0.01) of them
        "pre": np.zeros(C),  # ded_slow when the alarm began
    }


@njit_kernel
def decide_run(
    white,  # (T, H, C) the bank's whitened innovations
    ded,  # (T, C) the dedicated residuals
    y,  # (T, C) the readings
    lam,
    lam_iso,
    lam_d,
    hold_decay,
    warmup,
    lim_m,  # (H,) limits of M_h
    lim_s,  # (H,) limits of the slow consistency
    lim_d,  # (C,) limits of the noise check
    clip,  # (C,)
    lim_e,  # (C,) limits of |ded_fast|
    t_drift,
    step_ratio,
    settle,
    count,
    ewma,
    slow,
    prev,
    diff,
    held,
    breaks,
    last_held,
    reg,
    regj,
    alarmed,
    ded_fast,
    ded_slow,
    pre,
    NAMED,  # (T,) int: a channel named by another test (the GLR bank), −1 where none
    NAMED_KIND,  # (T,) int: the kind (1 bias, 2 drift) that test says, 0 where none
    SIGNAL,  # (T, 1 + 2C) out: the normalised checks (limit 1)
    CONS,  # (T, H) out: M_h / limit_h
    SLOW,  # (T, H) out: the slow consistency over its limit
    KIND,  # (T,) int out: 0 no alarm, 1..5 KINDS
    CHANNEL,  # (T,) int out: the sensor named (−1 none)
) -> None:
    """The checks and the decision of samples ``T`` (module docstring), state in place."""
    T, H, C = white.shape
    for k in range(T):
        count[0] += 1.0
        warm = count[0] <= warmup
        # model consistency
        for h in range(H):
            m = 0.0
            ms = 0.0
            for c in range(C):
                v = white[k, h, c]
                if math.isfinite(v):
                    ewma[h, c] = (1.0 - lam) * ewma[h, c] + lam * v
                    if c != h - 1:  # filter h reads every channel but h − 1
                        slow[h, c] = (1.0 - lam_iso) * slow[h, c] + lam_iso * v
                m += ewma[h, c] * ewma[h, c]
                ms += slow[h, c] * slow[h, c]
            CONS[k, h] = 0.0 if warm else m * (2.0 - lam) / lam / lim_m[h]
            SLOW[k, h] = 0.0 if warm else ms * (2.0 - lam_iso) / lam_iso / lim_s[h]
        SIGNAL[k, 0] = CONS[k, 0]
        # noise level and held values
        for c in range(C):
            yc = y[k, c]
            rep = 0.0
            if math.isfinite(prev[c]):
                d = abs(yc - prev[c])
                diff[c] = (1.0 - lam_d) * diff[c] + lam_d * min(d, clip[c])
                rep = 1.0 if d == 0.0 else 0.0
            else:
                diff[c] = 0.5 * lim_d[c]  # a neutral start: half its limit
            if rep == 0.0 and last_held[c] > 0.0:
                breaks[c] = (1.0 - hold_decay) * breaks[c] + 1.0
            else:
                breaks[c] = (1.0 - hold_decay) * breaks[c]
            held[c] = (1.0 - hold_decay) * held[c] + rep
            last_held[c] = rep
            prev[c] = yc
            SIGNAL[k, 1 + c] = 0.0 if warm else diff[c] / lim_d[c]
            SIGNAL[k, 1 + C + c] = held[c] / HOLD_COUNT
        alarm = False
        for j in range(SIGNAL.shape[1]):
            if SIGNAL[k, j] > 1.0:
                alarm = True
        if alarm and alarmed[0] == 0.0:  # a new alarm: the residual fits start here
            for c in range(C):
                pre[c] = ded_slow[c]
                for j in range(5):
                    reg[c, j] = 0.0
                regj[c, 0] = 0.0
                regj[c, 1] = 0.0
        alarmed[0] = 1.0 if alarm else 0.0
        for c in range(C):  # the residual's sums since the alarm began
            e = ded[k, c]
            if math.isfinite(e):
                ded_fast[c] = (1.0 - lam) * ded_fast[c] + lam * e
                ded_slow[c] = 0.99 * ded_slow[c] + 0.01 * e
            if alarm and math.isfinite(e):
                j = reg[c, 0]
                reg[c, 0] += 1.0
                reg[c, 1] += e
                reg[c, 2] += e * e
                reg[c, 3] += j * e
                regj[c, 0] += j
                regj[c, 1] += j * j
        if not alarm:
            KIND[k] = 0
            CHANNEL[k] = -1
            continue
        # which sensor, which kind
        best_hold, ch_hold = 1.0, -1
        best_noise, ch_noise = 1.0, -1
        for c in range(C):
            if SIGNAL[k, 1 + C + c] > best_hold:
                best_hold, ch_hold = SIGNAL[k, 1 + C + c], c
            if SIGNAL[k, 1 + c] > best_noise:
                best_noise, ch_noise = SIGNAL[k, 1 + c], c
        if ch_hold >= 0:
            CHANNEL[k] = ch_hold
            KIND[k] = _DROPOUT if breaks[ch_hold] > 0.5 else _STUCK
            continue
        if ch_noise >= 0:
            CHANNEL[k] = ch_noise
            KIND[k] = _NOISE
            continue
        c_best, v_best = NAMED[k], -1.0
        for h in range(1, H if c_best < 0 else 1):
            v = abs(ded_fast[h - 1]) / lim_e[h - 1] / max(SLOW[k, h], CONSISTENT)
            if v > v_best:
                v_best, c_best = v, h - 1
        CHANNEL[k] = c_best
        n = reg[c_best, 0]
        s1, s2, sje = reg[c_best, 1], reg[c_best, 2], reg[c_best, 3]
        sj, sjj = regj[c_best, 0], regj[c_best, 1]
        kind = _BIAS
        if n >= 3.0:
            mean = s1 / n
            sxx = sjj - sj * sj / n
            sxy = sje - sj * s1 / n
            rss = max(s2 - s1 * s1 / n - sxy * sxy / sxx, 1e-12)
            t = (sxy / sxx) / math.sqrt(rss / (n - 2.0) / sxx)
            growth = abs(sxy / sxx) * n
            if abs(t) >= t_drift and (t > 0.0) == (mean > 0.0) and growth > 0.5 * abs(mean):
                kind = _DRIFT
            elif n < settle and abs(mean) < step_ratio * abs(pre[c_best]):
                kind = _DRIFT
        KIND[k] = NAMED_KIND[k] if NAMED[k] >= 0 and NAMED_KIND[k] > 0 else kind
