"""Training the PPO agent (Stable-Baselines3) on ``FCC-control-v0``, and validating it.

:func:`train` runs SB3's PPO (``MlpPolicy``) on the native vector env
(:class:`~fcc_env.control_vector.FCCControlVectorEnv`, random faults per episode) for at most a
wall-clock budget, on training seeds only (:class:`PPOSettings`: ``seed`` ≥ 1000, every env
below the validation seeds 5000..), and exports the deterministic actor
(:class:`~evaluation.control.rl_policy.MLPPolicy`). :func:`validate` scores a policy on
validation episodes (seeds 5000..) beside the best fixed set points, with the control study's
harness (:mod:`evaluation.control.returns`).

The agent sees the observation scaled by running statistics (SB3's ``VecNormalize``, frozen
when exported) and the reward divided by :data:`REWARD_SCALE_USD`. Stable-Baselines3 is an
optional extra: ``pip install -e ".[rl]"``.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import random
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from evaluation.control import returns
from evaluation.control.policies import fixed_setpoints
from evaluation.control.rl_policy import FORMAT, MLPPolicy
from evaluation.control.rl_vec_env import require_sb3, sb3_vec_env
from fcc_common.progress import progress_bar
from fcc_common.validation import invalid
from fcc_env.control_draws import catalogue_option
from fcc_env.control_task import CONTROL_ENV_ID
from fcc_env.control_vector import NATIVE_CATALOGUES
from fcc_env.scenarios import scenario_names
from fcc_env.simulation import DEFAULT_MEMORY_BUDGET_BYTES

__all__ = [
    "REWARD_SCALE_USD",
    "TRAIN_SEED_MIN",
    "VALIDATION_SEED",
    "VALIDATION_SEEDS_MAX",
    "PPOSettings",
    "check_validation_seeds",
    "export_policy",
    "ppo_nbytes",
    "train",
    "validate",
]

#: The reward is divided by this before PPO sees it: the margin of a sample at the nominal
#: point (about 16 USD per 10-s sample, :mod:`fcc_env.control_task`), so a step's reward is
#: about 1 and a trip (200,000 USD) about -12,500.
REWARD_SCALE_USD = 16.0
#: Seeds: training from 1000, validation from 5000 (test seeds are 0..).
TRAIN_SEED_MIN, VALIDATION_SEED = 1000, 5000
#: Most validation seeds per scenario: as many as the test range (0..999) holds, so that
#: validating never costs more than the largest study.
VALIDATION_SEEDS_MAX = TRAIN_SEED_MIN
#: An upper bound of the observation's length in :func:`ppo_nbytes` (``FCC-control-v0`` has 11):
#: the check needs no env built.
_OBS_DIM_BOUND = 64


def check_validation_seeds(n_seeds: int) -> int:
    """``n_seeds`` validation seeds per scenario if 0 <= n <= :data:`VALIDATION_SEEDS_MAX`."""
    if isinstance(n_seeds, bool) or not isinstance(n_seeds, int):
        raise invalid("--val-seeds", n_seeds, "an integer")
    if not 0 <= n_seeds <= VALIDATION_SEEDS_MAX:
        raise invalid(
            "--val-seeds",
            n_seeds,
            f"0..{VALIDATION_SEEDS_MAX}",
            f"validation seeds {VALIDATION_SEED}..{VALIDATION_SEED + VALIDATION_SEEDS_MAX - 1}, "
            "as many as the test range holds",
        )
    return n_seeds


@dataclass(frozen=True)
class PPOSettings:
    """A training run: wall-clock budget, envs, seed and PPO's hyperparameters."""

    minutes: float = 30.0
    envs: int = 256
    seed: int = TRAIN_SEED_MIN
    n_steps: int = 128
    batch_size: int = 8192
    n_epochs: int = 5
    learning_rate: float = 1e-3
    gamma: float = 0.99
    hidden: tuple[int, ...] = (64, 64)
    reward_scale_usd: float = REWARD_SCALE_USD
    max_env_steps: int | None = None
    torch_threads: int = 1
    #: what the episodes draw (``FCC-control-v0``'s ``catalogue``): ``"paper"`` and ``"sensor"``
    #: run on the native vector env; ``"all"`` steps Python envs (``SyncVectorEnv``), as the
    #: native env carries no actuator fault (:mod:`fcc_env.control_vector`)
    catalogue: str = "paper"

    def __post_init__(self) -> None:
        catalogue_option(self.catalogue)
        if not 0 < self.minutes < math.inf:
            raise invalid("--minutes", self.minutes, "> 0, finite")
        if self.envs < 1:
            raise invalid("--envs", self.envs, ">= 1")
        if not TRAIN_SEED_MIN <= self.seed <= VALIDATION_SEED - self.envs:
            raise invalid(
                "--seed",
                self.seed,
                f"{TRAIN_SEED_MIN}..{VALIDATION_SEED - self.envs}",
                f"training seeds: env i gets seed + i, below the validation seeds "
                f"{VALIDATION_SEED}..; test seeds are 0..",
            )
        for name in ("n_steps", "n_epochs", "torch_threads"):
            if getattr(self, name) < 1:
                raise invalid(f"--{name.replace('_', '-')}", getattr(self, name), ">= 1")
        self._check_sb3()
        if not (self.hidden and all(h >= 1 for h in self.hidden)):
            raise invalid("--hidden", self.hidden, "one or more layer widths >= 1")
        if not (0 < self.learning_rate < 1 and 0 < self.gamma <= 1):
            raise invalid(
                "--lr/--gamma", (self.learning_rate, self.gamma), "0 < lr < 1, 0 < gamma <= 1"
            )
        if not 0 < self.reward_scale_usd < math.inf:
            raise invalid("--reward-scale", self.reward_scale_usd, "> 0, finite (USD)")
        if self.max_env_steps is not None and self.max_env_steps < 1:
            raise invalid("--max-env-steps", self.max_env_steps, ">= 1 or None")
        need = ppo_nbytes(self)
        if need > DEFAULT_MEMORY_BUDGET_BYTES:
            raise ValueError(
                f"--hidden {','.join(map(str, self.hidden))} with --batch-size {self.batch_size} "
                f"and --n-steps {self.n_steps} x --envs {self.envs} needs about "
                f"{need / 2**30:.3g} GiB (parameters with their gradients and Adam's moments, "
                f"activations, the rollout buffer), more than the memory budget of "
                f"{DEFAULT_MEMORY_BUDGET_BYTES / 2**30:g} GiB: choose narrower layers or smaller "
                "batches"
            )

    def _check_sb3(self) -> None:
        """Stable-Baselines3's PPO asserts these (``ppo.py``): refuse them by name first."""
        buffer = self.n_steps * self.envs
        if buffer < 2:
            raise invalid(
                "--n-steps x --envs",
                buffer,
                ">= 2",
                "PPO normalises advantages over one rollout: it needs two samples",
            )
        if not 2 <= self.batch_size <= buffer:
            raise invalid(
                "--batch-size",
                self.batch_size,
                f"2..{buffer} (--n-steps {self.n_steps} x --envs {self.envs})",
                "a minibatch of the rollout, of two samples at least",
            )
        cores = os.cpu_count() or 1
        if self.torch_threads > cores:
            raise invalid("--torch-threads", self.torch_threads, f"1..{cores} (the CPU cores)")


def ppo_nbytes(settings: PPOSettings) -> int:
    """Bytes PPO's training holds for ``settings`` (float32), an upper estimate: the actor's
    and critic's parameters four times (values, gradients, Adam's two moments), their
    activations over a minibatch three times (values, gradients, saved outputs), and the
    rollout buffer (observation, action and six scalars per env step)."""
    s = settings
    widths = [_OBS_DIM_BOUND, *s.hidden]
    params = sum((a + 1) * b for a, b in itertools.pairwise(widths))
    params = 2 * params + (s.hidden[-1] + 1) * 3  # both nets, the action (2) and value (1) heads
    activations = 3 * 2 * s.batch_size * sum(s.hidden)
    buffer = s.n_steps * s.envs * (_OBS_DIM_BOUND + 2 + 6)
    return 4 * (4 * params + activations + buffer)


def export_policy(model: Any, vecnorm: Any, settings: PPOSettings) -> MLPPolicy:
    """The actor of an SB3 PPO ``model`` with ``vecnorm``'s frozen observation statistics."""
    linear = [m for m in model.policy.mlp_extractor.policy_net if hasattr(m, "weight")]
    linear.append(model.policy.action_net)
    weights = {}
    for i, m in enumerate(linear):
        weights[f"layer{i}.weight"] = m.weight.detach().cpu().numpy().astype(np.float32)
        weights[f"layer{i}.bias"] = m.bias.detach().cpu().numpy().astype(np.float32)
    space = model.action_space
    config = {
        "format": FORMAT,
        "env_id": CONTROL_ENV_ID,
        "obs_dim": int(model.observation_space.shape[0]),
        "act_dim": int(space.shape[0]),
        "hidden": list(settings.hidden),
        "activation": "tanh",
        "obs_mean": vecnorm.obs_rms.mean.tolist(),
        "obs_var": vecnorm.obs_rms.var.tolist(),
        "obs_epsilon": float(vecnorm.epsilon),
        "obs_clip": float(vecnorm.clip_obs),
        "action_low": space.low.astype(float).tolist(),
        "action_high": space.high.astype(float).tolist(),
        "settings": asdict(settings),
    }
    return MLPPolicy(config, weights)


@contextlib.contextmanager
def _global_state_kept() -> Iterator[None]:
    """SB3 seeds Python's, NumPy's and torch's global generators, and training sets the thread
    counts of torch and numba: put them back after."""
    import numba
    import torch

    # the legacy global generator is what SB3 seeds: its state is what must be restored
    states = random.getstate(), np.random.get_state(), torch.get_rng_state()  # noqa: NPY002
    threads = torch.get_num_threads(), numba.get_num_threads()
    try:
        yield
    finally:
        random.setstate(states[0])
        np.random.set_state(states[1])  # noqa: NPY002
        torch.set_rng_state(states[2])
        torch.set_num_threads(threads[0])
        numba.set_num_threads(threads[1])


def train(
    settings: PPOSettings, *, progress: bool | None = False
) -> tuple[MLPPolicy, dict[str, Any]]:
    """PPO on ``settings.envs`` native vector envs until the wall-clock budget (or
    ``max_env_steps``) is spent. Returns the policy and a log (env steps, speed, returns).

    ``progress``: a bar on standard error (``None``: when it is a terminal;
    :mod:`fcc_common.progress`) counting env steps (out of ``max_env_steps`` when set) with the
    mean return of the last 20 finished episodes (USD); it reads the training, never steers it.
    """
    require_sb3()
    import numba
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import VecNormalize

    class Budget(BaseCallback):
        def __init__(self, seconds: float, bar: Any) -> None:
            super().__init__()
            self.seconds, self.rollouts, self.bar = seconds, [], bar

        def _on_training_start(self) -> None:
            self.t0 = time.perf_counter()

        def _on_step(self) -> bool:
            self.bar.update(self.num_timesteps - self.bar.n)
            return time.perf_counter() - self.t0 < self.seconds

        def _on_rollout_end(self) -> None:
            ended = self.training_env.venv.episode_returns
            mean = float(np.mean(ended[-20:])) if ended else None
            self.rollouts.append(
                {
                    "env_steps": int(self.num_timesteps),
                    "seconds": round(time.perf_counter() - self.t0, 1),
                    "mean_return_usd_last_episodes": mean,
                }
            )
            if mean is not None:
                self.bar.set_postfix_str(f"return {mean:,.0f} USD ({len(ended)} episodes)")

    s = settings
    with _global_state_kept():
        torch.set_num_threads(s.torch_threads)
        # numba's OpenMP workers spin-wait after each env step and starve torch's forward
        # passes (measured: 12 ms instead of 1 ms per step of 64 envs on two cores)
        numba.set_num_threads(1)
        if s.catalogue in NATIVE_CATALOGUES:
            venv = gym.make_vec(
                CONTROL_ENV_ID,
                s.envs,
                vectorization_mode="vector_entry_point",
                catalogue=s.catalogue,
            )
        else:
            venv = gym.make_vec(
                CONTROL_ENV_ID, s.envs, vectorization_mode="sync", catalogue=s.catalogue
            )
        env = VecNormalize(sb3_vec_env(venv, s.reward_scale_usd), norm_reward=False, gamma=s.gamma)
        model = PPO(
            "MlpPolicy",
            env,
            n_steps=s.n_steps,
            batch_size=s.batch_size,
            n_epochs=s.n_epochs,
            learning_rate=s.learning_rate,
            gamma=s.gamma,
            policy_kwargs={"net_arch": {"pi": list(s.hidden), "vf": list(s.hidden)}},
            seed=s.seed,
            device="cpu",
            verbose=0,
        )
        desc = f"PPO ({s.minutes:g} min budget)"
        with progress_bar(total=s.max_env_steps, desc=desc, unit="step", progress=progress) as bar:
            budget = Budget(60.0 * s.minutes, bar)
            t0 = time.perf_counter()
            model.learn(s.max_env_steps or 10**12, callback=budget)
            seconds = time.perf_counter() - t0
        policy = export_policy(model, env, s)
        env.close()
    log = {
        "env_steps": int(model.num_timesteps),
        "seconds": round(seconds, 1),
        "env_steps_per_s": round(model.num_timesteps / seconds, 1),
        "rollouts": budget.rollouts,
    }
    return policy, log


def validate(
    policy: Any, n_seeds: int, n_steps: int = 3999, *, progress: bool | None = False
) -> dict[str, Any]:
    """``policy`` and the best fixed set points on validation seeds 5000.. (each scenario at the
    paper's size and onset), with the control study's harness: mean returns and the gap.
    ``n_seeds``: at most :data:`VALIDATION_SEEDS_MAX`. ``progress`` as
    :func:`evaluation.control.returns.run_study`'s."""
    check_validation_seeds(n_seeds)
    seeds = range(VALIDATION_SEED, VALIDATION_SEED + n_seeds)
    scenarios = scenario_names()
    policies = [fixed_setpoints(), policy]
    scores = returns.run_study(policies, seeds, n_steps, scenarios, progress=progress)
    out: dict[str, Any] = {"seeds": list(seeds), "policies": {}}
    for s in returns.summarise(scores, reference=policy.name):
        by = {
            sc: np.mean([e.return_usd for e in scores if e.policy == s.policy and e.scenario == sc])
            for sc in scenarios
        }
        out["policies"][s.policy] = {
            "mean_return_usd": s.return_usd.estimate,
            "trips_per_100": s.trips_per_100,
            "by_scenario": {k: round(float(v), 1) for k, v in by.items()},
        }
    rl, fixed = (out["policies"][p.name]["mean_return_usd"] for p in (policy, fixed_setpoints()))
    out["rl_minus_fixed_usd"] = rl - fixed
    return out
