"""The native vector env of ``FCC-control-v0``: :class:`FCCVectorEnv` closed loop, with the reward.

The plant is :class:`~fcc_env.vector_env.FCCVectorEnv` (``regulatory=True``, the compiled
batch kernel); the reward and its terms come from its info arrays through the one definition,
:func:`~fcc_env.control_task.reward_term_arrays` and :func:`~fcc_env.control_task.total_reward`,
so a vector env seeded as ``SyncVectorEnv`` seeds its sub-envs gives their rewards and
``info["reward_terms"]`` bit for bit (``tests/fcc_env/test_control_vector.py``). Through
Gymnasium: ``gym.make_vec("FCC-control-v0", 256, vectorization_mode="vector_entry_point")``.

**Catalogues** (:data:`NATIVE_CATALOGUES`): ``"paper"`` (the default) and ``"sensor"`` (healthy
or a sensor fault: bias, drift or stuck, half of them on a loop transmitter;
:mod:`fcc_env.control_draws`), the issue's sensor-fault scenarios as a training draw. The
compiled loop applies a transmitter's bias, drift, stuck reading or extra noise before the
controllers read the measurement (:mod:`fcc_env.sensor_kernel`, the formula the single env
runs too), so each env draws its fault as ``FCCControlEnv`` does (its own generator, spawned
per episode) and gives the sync env's numbers bit for bit. ``"all"`` is refused by name: a
quarter of its draws are actuator faults (valve stiction, bias, stuck, the weak blower), whose
devices act in Python between the controllers and the plant and are not in the compiled loop;
run it with ``vectorization_mode="sync"``. A sensor dropout (a per-sample draw) is refused too;
no catalogue draws it.

>>> envs = FCCControlVectorEnv(2, scenario="nominal")
>>> _ = envs.reset(seed=0)
>>> obs, reward, terminated, truncated, info = envs.step(np.zeros((2, 2)))
>>> reward.shape, info["reward_terms"]["conversion"].shape
((2,), (2,))
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv

from fcc_common.validation import invalid
from fcc_env.control_draws import (
    catalogue_option,
    check_drawn_fields,
    draw_catalogue_fault,
    draws_random,
)
from fcc_env.control_task import (
    CONTROL_ENV_ID,
    REWARD_TERMS,
    EconomicReward,
    reward_term_arrays,
    total_reward,
)
from fcc_env.env import closed_loop_keyword
from fcc_env.scenarios import DEFAULT_N_SAMPLES
from fcc_env.vector_env import FCCVectorEnv

__all__ = ["CONTROL_VECTOR_ENTRY_POINT", "NATIVE_CATALOGUES", "FCCControlVectorEnv"]

CONTROL_VECTOR_ENTRY_POINT = "fcc_env.control_vector:FCCControlVectorEnv"
#: The catalogues the native vector env draws (module doc: why not ``"all"``).
NATIVE_CATALOGUES: tuple[str, ...] = ("paper", "sensor")


class _CataloguePlant(FCCVectorEnv):
    """:class:`FCCVectorEnv` whose random episodes draw their fault from a catalogue, each env
    as :meth:`FCCControlEnv.reset <fcc_env.control_task.FCCControlEnv.reset>` draws it: from a
    generator spawned from the env's own, seeded with the env's seed."""

    def __init__(self, num_envs: int, catalogue: str, **kwargs: Any) -> None:
        super().__init__(num_envs, **kwargs)
        self.catalogue = catalogue
        # each env's FCCControlEnv.np_random (the plant's generator is the parent's _rngs)
        self._draw_rngs: list[np.random.Generator | None] = [None] * self.num_envs

    def _episode_options(
        self, b: int, seed: int | None, options: dict[str, Any] | None
    ) -> dict[str, Any] | None:
        if seed is not None or self._draw_rngs[b] is None:
            self._draw_rngs[b] = seeding.np_random(seed)[0]
        if not draws_random(options, self._template.fault_spec.scenario):
            return options
        rng = self._draw_rngs[b].spawn(1)[0]
        fault = draw_catalogue_fault(rng, self._template.horizon, self.catalogue)
        options = {**(options or {}), "fault": fault}
        options.pop("scenario", None)
        return options


class FCCControlVectorEnv(VectorEnv):
    """``num_envs`` episodes of ``FCC-control-v0`` stepped together (Gymnasium 1.x semantics:
    NEXT_STEP autoreset, dict-of-array infos with ``_key`` masks; ``info["reward_terms"]`` is
    a dict of per-term arrays, masked as ``SyncVectorEnv`` batches a nested dict).

    Keywords are :class:`~fcc_env.control_task.FCCControlEnv`'s (``economics``, ``scenario``
    defaulting to ``"random"``, and ``FCC-closedloop-v0``'s) plus ``max_episode_steps`` and
    ``threads`` (:class:`~fcc_env.vector_env.FCCVectorEnv`'s, which also warns when the limit
    ends an episode before its fault onset; the thread policy is :mod:`fcc_env.vector_threads`).
    On an autoreset step an env's reward and terms are 0, as
    for a single env's reset.
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}  # noqa: RUF012

    def __init__(
        self,
        num_envs: int = 1,
        *,
        economics: Any = None,
        scenario: str = "random",
        regulatory: Any = True,
        max_episode_steps: int | None = DEFAULT_N_SAMPLES - 1,
        render_mode: str | None = None,
        catalogue: str = "paper",
        **kwargs: Any,
    ) -> None:
        self.economics = EconomicReward.from_option(economics)
        self.catalogue = catalogue_option(catalogue)
        if self.catalogue not in NATIVE_CATALOGUES:
            raise invalid(
                "catalogue",
                catalogue,
                f"{list(NATIVE_CATALOGUES)} on the native vector env",
                "its compiled loop carries no actuator fault (valve-stiction, valve-bias, "
                "valve-stuck, blower-capacity), a quarter of catalogue='all''s draws: use "
                "catalogue='sensor' (healthy or a sensor fault), or "
                "gym.make_vec(..., vectorization_mode='sync', catalogue='all')",
            )
        plant_kwargs = {
            "max_episode_steps": max_episode_steps,
            "render_mode": render_mode,
            "scenario": scenario,
            "regulatory": closed_loop_keyword(regulatory, CONTROL_ENV_ID),
            **kwargs,
        }
        if self.catalogue == "paper":
            self.plant = FCCVectorEnv(num_envs, **plant_kwargs)
        else:
            check_drawn_fields(self.catalogue, kwargs)  # FCCControlEnv refuses them too
            self.plant = _CataloguePlant(num_envs, self.catalogue, **plant_kwargs)
        self.num_envs = self.plant.num_envs
        self.max_episode_steps = self.plant.max_episode_steps
        self.single_observation_space = self.plant.single_observation_space
        self.single_action_space = self.plant.single_action_space
        self.observation_space = self.plant.observation_space
        self.action_space = self.plant.action_space
        self._dt_s = float(self.plant.config.sample_time_s)
        # envs whose next step is an autoreset (their episode ended on the last step)
        self._restart = np.zeros(self.num_envs, np.bool_)

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """:meth:`FCCVectorEnv.reset`: all envs, or those of ``options["reset_mask"]``."""
        mask = np.ones(self.num_envs, np.bool_)
        if options is not None and "reset_mask" in options:
            mask = np.asarray(options["reset_mask"], dtype=np.bool_)
        obs, infos = self.plant.reset(seed=seed, options=options)  # validates the mask
        self._restart[mask] = False
        zero = dict.fromkeys(REWARD_TERMS, np.zeros(self.num_envs))
        infos["reward_terms"] = self._masked(zero, mask)
        infos["_reward_terms"] = mask.copy()
        return obs, infos

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        obs, _, terminated, truncated, infos = self.plant.step(actions)
        terms = reward_term_arrays(infos, terminated, self.economics, self._dt_s)
        restarted = self._restart
        for name in REWARD_TERMS:  # an autoreset step is a reset: no reward
            terms[name] = np.where(restarted, 0.0, terms[name])
        reward = np.where(restarted, 0.0, total_reward(terms))
        full = np.ones(self.num_envs, np.bool_)
        infos["reward_terms"] = self._masked(terms, full)
        infos["_reward_terms"] = full
        self._restart = terminated | truncated
        return obs, reward, terminated, truncated, infos

    def close_extras(self, **kwargs: Any) -> None:
        self.plant.close()

    @staticmethod
    def _masked(terms: dict[str, np.ndarray], mask: np.ndarray) -> dict[str, np.ndarray]:
        """``terms`` as ``SyncVectorEnv`` batches a nested info dict: 0 outside ``mask``."""
        out: dict[str, np.ndarray] = {}
        for name in REWARD_TERMS:
            out[name] = np.where(mask, terms[name], 0.0)
            out[f"_{name}"] = mask.copy()
        return out
