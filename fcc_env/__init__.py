"""FCC converter (riser + two-stage regenerator) as a Gymnasium environment with faults f1–f4
(and any added with :func:`register_fault`).

The modules, by job:

- :mod:`~fcc_env.params`, :mod:`~fcc_env.physics`: the frozen parameters; the pure right-hand
  side, the measurement map and the steady state; :mod:`~fcc_env.integrator`: RK4 stepping;
- :mod:`~fcc_env.faults`: the fault registry (:data:`FAULTS`, :func:`register_fault`);
  :mod:`~fcc_env.sensor_faults`: the sensor faults on a chosen measured channel (bias, drift,
  stuck, noise, dropout), registered on import, and :mod:`~fcc_env.sensor_kernel`, their
  compiled transmitter (all but the dropout), which the native vector env runs too;
  :mod:`~fcc_env.actuator_faults`: the actuator
  faults (valve stiction, bias, stuck; blower capacity), registered on import, with
  :mod:`~fcc_env.stiction`, the valve-stiction model of Choudhury et al. 2005;
  :mod:`~fcc_env.scenarios`: :class:`FaultSpec`, the one typed fault request;
  :mod:`~fcc_env.excitation`: the operating program; :mod:`~fcc_env.plant`: :class:`PlantConfig`,
  the noise and the envelope; :mod:`~fcc_env.effects`, :mod:`~fcc_env.uncertainty`: undeclared
  effects and per-episode plant draws;
- :mod:`~fcc_env.episode_setup`: one episode's set-up, shared by :mod:`~fcc_env.env` (``FCC-v0``) and
  :mod:`~fcc_env.simulation` (:func:`simulate_episodes`, which takes the fault and the plant whole;
  :mod:`~fcc_env.env_keywords`: the env's keywords as those objects, :func:`env_request`);
- :mod:`~fcc_env.regulatory`, :mod:`~fcc_env.closed_loop`: the regulatory layer and what a
  closed-loop plant shows (``FCC-closedloop-v0``); :mod:`~fcc_env.closed_loop_analysis`: the
  linearised closed loop's eigenvalues; :mod:`~fcc_env.closed_loop_report` and
  :mod:`~fcc_env.closed_loop_figures`: the closed-loop report (responses, masking, terminations);
- :mod:`~fcc_env.control_task`: ``FCC-control-v0``, the closed loop with an economic reward;
  :mod:`~fcc_env.control_draws`: what its random episodes draw (the paper's faults, the whole catalogue by fault class, or the sensor faults);
- :mod:`~fcc_env.vector_env`, :mod:`~fcc_env.control_vector`: native vector envs (N episodes in
  one compiled loop) of ``FCC-v0``/``FCC-closedloop-v0`` and of ``FCC-control-v0``, and
  :mod:`~fcc_env.vector_threads`, the numba threads their step runs on;
- :mod:`~fcc_env.plotting`, :mod:`~fcc_env.render`: figures and the env's ``rgb_array`` frame;
  :mod:`~fcc_env.dataset_schema`: units and roles in a dataset's Parquet schema;
- :mod:`~fcc_env.generate`, :mod:`~fcc_env.demo`: the commands (the simulator's speed:
  ``python -m bench.simulator_speed``).

A :class:`FaultSpec` and a :class:`PlantConfig` are validated once, when built, and travel whole
from ``gym.make`` or :func:`simulate_episodes` to the physics; the env's keywords
(``scenario=``, ``fault_time=``, ``valve_beta=``...) are turned into them once, on entry.

Importing the package registers ``FCC-v0``:

>>> import gymnasium as gym
>>> import fcc_env
>>> env = gym.make("FCC-v0", scenario="f1")
>>> env.observation_space.shape
(8,)
"""

import os

from gymnasium.envs.registration import register, registry

from fcc_env.actuator_faults import ACTUATOR_FAULTS  # registers the actuator faults
from fcc_env.control_task import CONTROL_ENV_ID, EconomicReward
from fcc_env.env import CLOSED_LOOP_ENV_ID, ENV_ID
from fcc_env.env_keywords import env_request
from fcc_env.excitation import Excitation
from fcc_env.faults import (
    FAULTS,
    PAPER_FAULTS,
    FaultDefinition,
    Scenario,
    fault_names,
    path_fault,
    register_fault,
    scenario_names,
    unregister_fault,
)
from fcc_env.integrator import integrate_step
from fcc_env.params import (
    INPUT_NAMES,
    MEASUREMENT_NAMES,
    MEASUREMENTS,
    NOMINAL_INPUTS,
    STATE_NAMES,
    FCCParams,
    Measurement,
)
from fcc_env.physics import measure, rhs, steady_state
from fcc_env.plant import PlantConfig
from fcc_env.regulatory import RegulatoryLayer, SetpointProgram
from fcc_env.scenarios import DEFAULT_N_SAMPLES, FaultProfile, FaultSpec
from fcc_env.sensor_faults import SENSOR_FAULTS  # registers the sensor faults
from fcc_env.simulation import BatchResult, simulate_episodes

# numba's OpenMP threading layer (libgomp) reads OMP_WAIT_POLICY once, when its thread pool
# starts (the first parallel kernel): PASSIVE makes the threads that wait at a kernel's barrier
# sleep instead of spinning, which on a busy machine took the cores from the threads still
# working (the native vector env at 1024 envs on two threads: 2x slower than one thread spinning,
# 1.3x faster passive; lab/env-speed.md). A value set in the environment is kept; the value
# also reaches OpenMP runtimes loaded later (torch's), as docs/environment.md says.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

#: 3999 steps = 4000 samples including the reset observation (the paper's horizon).
MAX_EPISODE_STEPS = DEFAULT_N_SAMPLES - 1


# The plant ids have a native vector env (gym.make_vec(..., vectorization_mode=
# "vector_entry_point")), which Gymnasium refuses for a spec with additional wrappers: so the
# check that gym.make's max_episode_steps does not end an episode before its fault onset
# (fcc_env.env.OnsetHorizonCheck) is the vector env's own, and a wrapper a user adds for single
# envs (use horizon= to shorten an episode: an onset outside it is refused).
# The closed-loop id has classes of its own, which refuse regulatory=False (gym.make would
# otherwise let it override the registered True and build the open-loop plant silently).
for _id, _kwargs, _env, _vector in (
    (ENV_ID, {}, "FCCEnv", "FCCVectorEnv"),
    (CLOSED_LOOP_ENV_ID, {"regulatory": True}, "FCCClosedLoopEnv", "FCCClosedLoopVectorEnv"),
):
    if _id not in registry:
        register(
            id=_id,
            entry_point=f"fcc_env.env:{_env}",
            vector_entry_point=f"fcc_env.vector_env:{_vector}",
            max_episode_steps=MAX_EPISODE_STEPS,
            kwargs=_kwargs,
        )

# The control task has a native vector env too, so, as for the plant ids, no additional wrapper:
# its vector env warns of a limit before the onset by itself (FCCVectorEnv's check).
if CONTROL_ENV_ID not in registry:
    register(
        id=CONTROL_ENV_ID,
        entry_point="fcc_env.control_task:FCCControlEnv",
        vector_entry_point="fcc_env.control_vector:FCCControlVectorEnv",
        max_episode_steps=MAX_EPISODE_STEPS,
    )

__version__ = "0.1.0"
#: Bumped whenever the simulated numbers change (written into generated datasets).
MODEL_VERSION = "fcc-model-2026.1"

__all__ = [
    "ACTUATOR_FAULTS",
    "CLOSED_LOOP_ENV_ID",
    "CONTROL_ENV_ID",
    "DEFAULT_N_SAMPLES",
    "ENV_ID",
    "FAULTS",
    "INPUT_NAMES",
    "MAX_EPISODE_STEPS",
    "MEASUREMENTS",
    "MEASUREMENT_NAMES",
    "MODEL_VERSION",
    "NOMINAL_INPUTS",
    "PAPER_FAULTS",
    "SENSOR_FAULTS",
    "STATE_NAMES",
    "BatchResult",
    "EconomicReward",
    "Excitation",
    "FCCParams",
    "FaultDefinition",
    "FaultProfile",
    "FaultSpec",
    "Measurement",
    "PlantConfig",
    "RegulatoryLayer",
    "Scenario",
    "SetpointProgram",
    "env_request",
    "fault_names",
    "integrate_step",
    "measure",
    "path_fault",
    "register_fault",
    "rhs",
    "scenario_names",
    "simulate_episodes",
    "steady_state",
    "unregister_fault",
]
