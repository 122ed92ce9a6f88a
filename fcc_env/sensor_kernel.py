"""The compiled transmitter of the sensor faults that need no per-sample draw: bias, drift,
stuck, noise (:mod:`fcc_env.sensor_faults` defines them; this is their one formula).

:func:`sensor_read` is what :class:`fcc_env.sensor_faults.ChannelSensor` calls per sample for
these kinds (the single env, batch simulation) and what the native vector env
(:mod:`fcc_env.vector_env`) calls inside its compiled loop, so the two give the same bits.
A dropout needs one uniform draw per sample from the episode's fault stream: it stays in
Python, and the native vector env refuses it
(:func:`fcc_env.sensor_faults.compiled_transmitter`).

>>> y, z, held = np.full(8, 500.0), np.zeros(8), np.zeros(2)
>>> sensor_read(BIAS, 10, y, z, 0, 3.0, 5, 0, 10.0 / 3600.0, held, False)
True
>>> float(y[0])
503.0
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = [
    "BIAS",
    "DRIFT",
    "NATIVE_SENSOR_KINDS",
    "NOISE",
    "NO_SENSOR",
    "STUCK",
    "sensor_read",
]

#: Kind codes of the compiled transmitter (0: no sensor fault in the episode).
NO_SENSOR, BIAS, DRIFT, STUCK, NOISE = 0, 1, 2, 3, 4
#: The kinds :func:`sensor_read` carries, by :class:`~fcc_env.sensor_faults.ChannelSensor` kind.
NATIVE_SENSOR_KINDS: dict[str, int] = {"bias": BIAS, "drift": DRIFT, "stuck": STUCK, "noise": NOISE}


@numba.njit(cache=True, nogil=True, error_model="numpy")
def sensor_read(
    kind: int,
    k: int,
    y: np.ndarray,
    z: np.ndarray,
    ch: int,
    magnitude: float,
    onset: int,
    ramp: int,
    hours_per_sample: float,
    held: np.ndarray,
    has_held: bool,
) -> bool:
    """Sample ``k`` as the faulty transmitter on channel ``ch`` delivers it, in place: ``y``
    the noise-free measurements ``(8,)``, ``z`` the noise's standard-normal draws ``(8,)``
    (the noise is added afterwards). ``held`` ``(2,)`` is the channel's last delivered
    ``(y, z)`` (valid when ``has_held``); returns the new ``has_held``.

    The size is ``magnitude`` × the fault's fraction (:meth:`EpisodeFault.fraction`: 0 before
    ``onset``, reached linearly over ``ramp`` samples, 0 = abrupt). A stuck transmitter holds
    the reading of the sample before the onset (with gain ``1 − m`` around it for ``m < 1``);
    every other kind records each delivered reading."""
    frac = 0.0
    if k >= onset:
        frac = min(1.0, (k - onset + 1) / ramp) if ramp > 0 else 1.0
    m = magnitude * frac
    if kind == BIAS:
        y[ch] += m
    elif kind == DRIFT:
        # the hours of fault so far (the onset sample counts as one)
        y[ch] += m * (k - onset + 1) * hours_per_sample if frac != 0.0 else 0.0
    elif kind == NOISE:
        z[ch] *= 1.0 + m
    elif kind == STUCK and frac != 0.0 and has_held:
        y[ch] = held[0] + (1.0 - m) * (y[ch] - held[0])
        z[ch] = held[1] + (1.0 - m) * (z[ch] - held[1])
    if kind != STUCK or frac == 0.0 or not has_held:
        held[0] = y[ch]
        held[1] = z[ch]
        return True
    return has_held
