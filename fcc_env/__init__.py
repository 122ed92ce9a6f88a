"""FCC converter (riser + two-stage regenerator) as a Gymnasium environment with faults f1–f4.

Importing the package registers ``FCC-v0``:

>>> import gymnasium as gym
>>> import fcc_env
>>> env = gym.make("FCC-v0", scenario="f1")
>>> env.observation_space.shape
(8,)
"""

from gymnasium.envs.registration import register, registry

from fcc_env.params import (
    INPUT_NAMES,
    MEASUREMENT_NAMES,
    MEASUREMENTS,
    NOMINAL_INPUTS,
    STATE_NAMES,
    FCCParams,
    Measurement,
)
from fcc_env.physics import integrate_step, measure, rhs, steady_state
from fcc_env.scenarios import (
    DEFAULT_N_SAMPLES,
    FAULTS,
    SCENARIOS,
    Excitation,
    FaultProfile,
    FaultSpec,
    Scenario,
)
from fcc_env.simulation import BatchResult, PlantConfig, simulate_episodes

ENV_ID = "FCC-v0"
#: 3999 steps = 4000 samples including the reset observation (the paper's horizon).
MAX_EPISODE_STEPS = DEFAULT_N_SAMPLES - 1

if ENV_ID not in registry:
    register(id=ENV_ID, entry_point="fcc_env.env:FCCEnv", max_episode_steps=MAX_EPISODE_STEPS)

__version__ = "0.1.0"
#: Bumped whenever the simulated numbers change (written into generated datasets).
MODEL_VERSION = "fcc-model-2026.1"

__all__ = [
    "DEFAULT_N_SAMPLES",
    "ENV_ID",
    "FAULTS",
    "INPUT_NAMES",
    "MAX_EPISODE_STEPS",
    "MEASUREMENTS",
    "MEASUREMENT_NAMES",
    "MODEL_VERSION",
    "NOMINAL_INPUTS",
    "SCENARIOS",
    "STATE_NAMES",
    "BatchResult",
    "Excitation",
    "FCCParams",
    "FaultProfile",
    "FaultSpec",
    "Measurement",
    "PlantConfig",
    "Scenario",
    "integrate_step",
    "measure",
    "rhs",
    "simulate_episodes",
    "steady_state",
]
