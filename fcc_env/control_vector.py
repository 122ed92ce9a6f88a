"""The native vector env of ``FCC-control-v0``: :class:`FCCVectorEnv` closed loop, with the reward.

The plant is :class:`~fcc_env.vector_env.FCCVectorEnv` (``regulatory=True``, the compiled
batch kernel); the reward and its terms come from its info arrays through the one definition,
:func:`~fcc_env.control_task.reward_term_arrays` and :func:`~fcc_env.control_task.total_reward`,
so a vector env seeded as ``SyncVectorEnv`` seeds its sub-envs gives their rewards and
``info["reward_terms"]`` bit for bit (``tests/fcc_env/test_control_vector.py``). Through
Gymnasium: ``gym.make_vec("FCC-control-v0", 256, vectorization_mode="vector_entry_point")``.

>>> envs = FCCControlVectorEnv(2, scenario="nominal")
>>> _ = envs.reset(seed=0)
>>> obs, reward, terminated, truncated, info = envs.step(np.zeros((2, 2)))
>>> reward.shape, info["reward_terms"]["conversion"].shape
((2,), (2,))
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv

from fcc_common.validation import invalid
from fcc_env.control_draws import catalogue_option
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

__all__ = ["CONTROL_VECTOR_ENTRY_POINT", "FCCControlVectorEnv"]

CONTROL_VECTOR_ENTRY_POINT = "fcc_env.control_vector:FCCControlVectorEnv"


class FCCControlVectorEnv(VectorEnv):
    """``num_envs`` episodes of ``FCC-control-v0`` stepped together (Gymnasium 1.x semantics:
    NEXT_STEP autoreset, dict-of-array infos with ``_key`` masks; ``info["reward_terms"]`` is
    a dict of per-term arrays, masked as ``SyncVectorEnv`` batches a nested dict).

    Keywords are :class:`~fcc_env.control_task.FCCControlEnv`'s (``economics``, ``scenario``
    defaulting to ``"random"``, and ``FCC-closedloop-v0``'s) plus ``max_episode_steps`` and
    ``threads`` (:class:`~fcc_env.vector_env.FCCVectorEnv`'s, which also warns when the limit
    ends an episode before its fault onset, and whose module doc gives the thread policy). On an autoreset step an env's reward and terms are 0, as
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
        if catalogue_option(catalogue) != "paper":
            raise invalid(
                "catalogue",
                catalogue,
                "'paper' on the native vector env",
                "its compiled loop carries no sensor or actuator fault; for catalogue='all' use "
                "gym.make_vec(..., vectorization_mode='sync', catalogue='all')",
            )
        self.plant = FCCVectorEnv(
            num_envs,
            max_episode_steps=max_episode_steps,
            render_mode=render_mode,
            scenario=scenario,
            regulatory=closed_loop_keyword(regulatory, CONTROL_ENV_ID),
            **kwargs,
        )
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
