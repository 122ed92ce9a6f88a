"""The env's keywords as the typed requests they stand for.

``gym.make("FCC-v0", scenario="f1", noise_scale=2.0)`` takes the fault and the plant as loose
keywords, as Gymnasium users expect; everything behind the env takes them whole, as a
:class:`~fcc_env.FaultSpec` and a :class:`~fcc_env.PlantConfig`. :func:`env_request` is that
bridge as a function, for code that holds the env's keywords and wants batch simulation::

    fault, plant = env_request(scenario="f1", fault_time=150, noise_scale=2.0)
    simulate_episodes(seeds, 300, fault=fault, plant=plant)

>>> fault, plant = env_request(scenario="f2", noise_scale=0.5)
>>> fault.scenario, plant.noise_scale
('f2', 0.5)
"""

from __future__ import annotations

from typing import Any

from fcc_env.plant import ENV_PLANT_KEYWORDS, PlantConfig
from fcc_env.scenarios import ENV_FAULT_KEYWORDS, FaultSpec, fault_from_request

__all__ = ["env_request"]


def env_request(**keywords: Any) -> tuple[FaultSpec, PlantConfig]:
    """The :class:`FaultSpec` and :class:`PlantConfig` that ``gym.make``'s fault keywords
    (``scenario``, ``fault_time``, ``fault_magnitude``, ``fault_profile``, ``ramp_samples``) and
    plant keywords (``valve_beta``, ``sample_time_s``, ``rk4_substeps``, ``excitation``,
    ``noise_scale``, ``params``, ``regulatory``) build; ``None`` means not given. Any other
    keyword raises ``TypeError`` naming the allowed ones."""
    allowed = (*ENV_FAULT_KEYWORDS, *ENV_PLANT_KEYWORDS)
    unknown = sorted(set(keywords) - set(allowed))
    if unknown:
        raise TypeError(f"unknown env keyword(s) {unknown}; allowed: {list(allowed)}")
    fault = fault_from_request(None, {k: keywords.get(k) for k in ENV_FAULT_KEYWORDS})
    plant = PlantConfig.build(**{k: keywords.get(k) for k in ENV_PLANT_KEYWORDS})
    return fault, plant
