"""A Gymnasium vector env as a Stable-Baselines3 ``VecEnv`` (:func:`sb3_vec_env`).

Stable-Baselines3 is an optional extra (``pip install -e ".[rl]"``): it is imported when an
adapter is built, never when this module is, and :func:`require_sb3` says how to install it.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv

from fcc_common.validation import invalid

__all__ = ["INSTALL_HINT", "require_sb3", "sb3_vec_env"]

INSTALL_HINT = 'Stable-Baselines3 is not installed: pip install -e ".[rl]"'


def require_sb3() -> None:
    """Raise an ``ImportError`` that says how to install Stable-Baselines3, where it is missing."""
    try:
        import stable_baselines3  # noqa: F401
    except ImportError as e:
        raise ImportError(INSTALL_HINT) from e


def sb3_vec_env(venv: VectorEnv, reward_scale: float = 1.0) -> Any:
    """``venv`` (a Gymnasium 1.x vector env with NEXT_STEP autoreset) as an SB3 ``VecEnv``.

    SB3 expects an ended episode to be reset within the step that ended it, its last
    observation in ``info["terminal_observation"]`` and ``info["TimeLimit.truncated"]`` set
    on a truncation (PPO bootstraps the value there). Gymnasium's NEXT_STEP env would instead
    spend the next step on the reset, so the ended envs are reset at once through
    ``options={"reset_mask": done}``, and the next step steps every env. Rewards are divided by
    ``reward_scale``; ``info["episode"]`` has the ended episode's return in the env's unit
    (``r``), its length (``l``) and the wall time (``t``) for SB3's logger. The class is built
    on first use so that SB3 stays optional.
    """
    require_sb3()
    return _adapter_class()(venv, reward_scale)


def _adapter_class() -> type:
    from stable_baselines3.common.vec_env import VecEnv

    class _Adapter(VecEnv):
        def __init__(self, venv: VectorEnv, reward_scale: float) -> None:
            mode = venv.metadata.get("autoreset_mode")
            if mode != AutoresetMode.NEXT_STEP:
                raise invalid("autoreset_mode", mode, "AutoresetMode.NEXT_STEP")
            self.venv, self.reward_scale = venv, float(reward_scale)
            n = venv.num_envs
            super().__init__(n, venv.single_observation_space, venv.single_action_space)
            self._returns, self._lengths = np.zeros(n), np.zeros(n, np.int64)
            self.episode_returns: list[float] = []
            self._t0 = time.perf_counter()

        def reset(self) -> np.ndarray:
            seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
            obs, _ = self.venv.reset(seed=seeds)
            self._reset_seeds()
            self._returns[:], self._lengths[:] = 0.0, 0
            return obs

        def step_async(self, actions: np.ndarray) -> None:
            self._actions = np.asarray(actions)

        def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict]]:
            obs, reward, terminated, truncated, _ = self.venv.step(self._actions)
            done = terminated | truncated
            self._returns += reward
            self._lengths += 1
            infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
            if done.any():
                fresh, _ = self.venv.reset(options={"reset_mask": done})
                for b in np.flatnonzero(done):
                    infos[b]["terminal_observation"] = obs[b].copy()
                    infos[b]["TimeLimit.truncated"] = bool(truncated[b] and not terminated[b])
                    r, n = float(self._returns[b]), int(self._lengths[b])
                    infos[b]["episode"] = {"r": r, "l": n, "t": time.perf_counter() - self._t0}
                    self.episode_returns.append(r)
                obs = np.where(done[:, None], fresh, obs)
                self._returns[done], self._lengths[done] = 0.0, 0
            return obs, (reward / self.reward_scale).astype(np.float32), done, infos

        def close(self) -> None:
            self.venv.close()

        def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
            return [getattr(self.venv, attr_name)] * len(self._get_indices(indices))

        def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
            setattr(self.venv, attr_name, value)

        def env_method(self, method_name: str, *args: Any, indices: Any = None, **kw: Any) -> list:
            raise invalid("env_method", method_name, "none", "a native vector env has no sub-envs")

        def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
            return [False] * len(self._get_indices(indices))

    return _Adapter
