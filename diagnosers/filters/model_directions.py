"""Fault directions from the model, not from fault data: each fault's innovation signature on
the detector's own fitted model (:func:`innovation_directions`).

A grey-box detector knows, from the published model, which parameter (or path) each fault
changes: the fault registry (:mod:`fcc_env.faults`) says so. It therefore never needs a
labelled faulty record to know where a fault moves the innovations: it simulates its own
fitted model twice on the same seed, healthy and with the fault applied at the registry's size
(a noise twin: the same excitation and noise), runs its own filter on both, and takes the mean
difference of the whitened innovations over a window after the onset. The twin's noise cancels
in the difference, so a few seeds give a clean direction; the filter's input walks and steps are
the same as on real records (they run on noisy readings), which a noise-free run would not show.

One direction per fault and window: a fault's signature is dynamic (f1 moves T_rx at once, f3
builds over minutes while the filter's input walks absorb part of each fault), so a short and a
long window each give one.

A sensor fault is a fault of one channel's transmitter (``sensor-bias`` on ``T_rx``): its
direction is simulated the same way, with the channel named (:func:`sensor_fault_entries`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from diagnosers.filters.state_estimator import FCCStateEstimator
from fcc_common.validation import Integer, Options, Real, check, invalid
from fcc_env.params import MEASUREMENT_NAMES
from fcc_env.plant import PlantConfig
from fcc_env.scenarios import FaultSpec, fault_definition
from fcc_env.simulation import simulate_episodes

__all__ = [
    "SENSOR_DIRECTION_KINDS",
    "fault_label",
    "innovation_directions",
    "own_plant",
    "sensor_fault_entries",
]

#: the sensor-fault kinds a detector can add a direction for on every measured channel (the
#: registered ``sensor-<kind>`` faults that shift a reading; stuck, noise and dropout change its
#: variance or freeze it, which no mean direction describes)
SENSOR_DIRECTION_KINDS = ("bias", "drift")
#: a fault to simulate: a registered fault's name, or a channel fault's (name, channel)
FaultEntry = str | tuple[str, str]


def sensor_fault_entries(
    kinds: Sequence[str], channels: Sequence[str] = MEASUREMENT_NAMES
) -> list[tuple[str, str]]:
    """``(scenario, channel)`` of each sensor-fault kind (kind-major) on each of ``channels``:
    the entries :func:`innovation_directions` takes for them; ``ValueError`` for a kind not in
    :data:`SENSOR_DIRECTION_KINDS` or a channel not measured."""
    for k in kinds:
        check("sensor_directions", k, Options(SENSOR_DIRECTION_KINDS))
    for c in channels:
        check("channel", c, Options(MEASUREMENT_NAMES))
    return [(f"sensor-{k}", c) for k in kinds for c in channels]


def fault_label(fault: FaultEntry) -> str:
    """A fault entry's name in signal names: ``f1``, ``sensor-drift@T_rx``."""
    return fault if isinstance(fault, str) else f"{fault[0]}@{fault[1]}"


def own_plant(est: FCCStateEstimator) -> PlantConfig:
    """The plant the estimator's own model describes: its parameters, noise scale, sample time
    and loop mode (the default regulatory layer in closed loop, the spec's published tuning)."""
    c = est.config
    return PlantConfig.build(
        params=est.params,
        valve_beta=est.params.beta_sv,
        noise_scale=c.noise_scale,
        sample_time_s=c.sample_time_s,
        rk4_substeps=c.rk4_substeps,
        regulatory=True if c.closed_loop else None,
    )


def innovation_directions(
    est: FCCStateEstimator,
    faults: Sequence[FaultEntry],
    *,
    seeds: Sequence[int],
    onset: int,
    windows: Sequence[int],
    size: float = 1.0,
) -> np.ndarray:
    """Unit directions ``(len(faults) · len(windows), 8)`` (fault-major) of each fault's
    whitened-innovation signature on ``est``'s own model (module docstring).

    Args:
        est: the detector's filter; its parameters and noise are the simulated plant's.
        faults: registered faults (:func:`fcc_env.fault_names`), or a channel fault's
            ``(scenario, channel)`` (:func:`sensor_fault_entries`).
        seeds: the simulations' seeds (the twins share each).
        onset: the faults' onset sample (after the filter has settled).
        windows: samples after the onset each direction averages.
        size: the simulated size as a multiple of each fault's registered default magnitude.

    A direction that comes out zero (a fault the filter does not see in that window) stays zero:
    its GLR then never alarms.
    """
    onset = check("onset", onset, Integer(1))
    windows = tuple(check("windows", w, Integer(1)) for w in windows)
    size = check("size", size, Real(0.0, 10.0, closed="right"))
    seeds = list(seeds)
    if not seeds or not faults:
        raise invalid("seeds/faults", (seeds, list(faults)), "at least one of each")
    plant = own_plant(est)
    n = onset + max(windows)
    healthy = _whitened(est, simulate_episodes(seeds, n, plant=plant).observations)
    out = np.zeros((len(faults) * len(windows), healthy.shape[-1]))
    for i, fault in enumerate(faults):
        name, channel = (fault, None) if isinstance(fault, str) else fault
        d = fault_definition(name)
        spec = FaultSpec(
            scenario=name, onset=onset, magnitude=size * d.default_magnitude, channel=channel
        )
        faulty = _whitened(est, simulate_episodes(seeds, n, fault=spec, plant=plant).observations)
        for j, w in enumerate(windows):
            diff = faulty[:, onset : onset + w] - healthy[:, onset : onset + w]
            mean = np.nanmean(diff.reshape(-1, diff.shape[-1]), axis=0)
            out[i * len(windows) + j] = np.where(np.isfinite(mean), mean, 0.0)
    norm = np.linalg.norm(out, axis=1, keepdims=True)
    return np.divide(out, norm, out=np.zeros_like(out), where=norm > 0)


def _whitened(est: FCCStateEstimator, obs: np.ndarray) -> np.ndarray:
    return est.filter(np.asarray(obs, dtype=np.float64), innovation_cov=False).whitened
