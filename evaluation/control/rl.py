"""``python -m evaluation.control.rl``: a PPO agent (Stable-Baselines3) on ``FCC-control-v0``.

``train`` runs SB3's PPO (``MlpPolicy``) on the native vector env
(:class:`~fcc_env.control_vector.FCCControlVectorEnv`, random faults per episode) for at most
``--minutes`` of wall clock, on training seeds only (``--seed`` ≥ 1000, every env below the
validation seeds 5000..), then scores the deterministic policy on ``--val-seeds`` validation
episodes per scenario (seeds 5000..) beside the best fixed set points. ``evaluate`` adds the
saved agent to the control study (:mod:`evaluation.control.returns`, test seeds 0..): the same
harness and table as the baselines, with its loss against the oracle.

The agent sees the observation scaled by running statistics (SB3's ``VecNormalize``, frozen
when saved) and the reward divided by :data:`REWARD_SCALE_USD`. The saved policy is
``policy.npz`` (the actor's weights, no pickle) and ``policy.json`` (architecture, scaling,
action bounds, the training settings): loading runs no code from the files and needs neither
SB3 nor torch. Stable-Baselines3 is an optional extra: ``pip install -e ".[rl]"``.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import json
import random
import time
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv

from evaluation.control import returns
from evaluation.control.policies import fixed_setpoints
from fcc_common.invocation import check_out_path, command_parser, out_path, run_command
from fcc_common.io import atomic_write_json
from fcc_common.validation import invalid
from fcc_env.control_task import CONTROL_ENV_ID
from fcc_env.scenarios import scenario_names

__all__ = [
    "REWARD_SCALE_USD",
    "MLPPolicy",
    "PPOSettings",
    "load_policy",
    "save_policy",
    "sb3_vec_env",
    "train",
    "validate",
]

#: The reward is divided by this before PPO sees it: the margin of a sample at the nominal
#: point (about 16 USD per 10-s sample, :mod:`fcc_env.control_task`), so a step's reward is
#: about 1 and a trip (200,000 USD) about -12,500.
REWARD_SCALE_USD = 16.0
#: Seeds: training from 1000, validation from 5000 (test seeds are 0..).
TRAIN_SEED_MIN, VALIDATION_SEED = 1000, 5000
FORMAT = "fcc-rl-policy/1"
INSTALL_HINT = 'Stable-Baselines3 is not installed: pip install -e ".[rl]"'


def _require_sb3() -> None:
    try:
        import stable_baselines3  # noqa: F401
    except ImportError as e:
        raise ImportError(INSTALL_HINT) from e


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

    def __post_init__(self) -> None:
        if not self.minutes > 0:
            raise invalid("--minutes", self.minutes, "> 0")
        if self.envs < 1:
            raise invalid("--envs", self.envs, ">= 1")
        if not TRAIN_SEED_MIN <= self.seed <= VALIDATION_SEED - self.envs:
            raise invalid(
                "--seed", self.seed, f"{TRAIN_SEED_MIN}..{VALIDATION_SEED - self.envs}",
                f"training seeds: env i gets seed + i, below the validation seeds "
                f"{VALIDATION_SEED}..; test seeds are 0..",
            )  # fmt: skip
        for name in ("n_steps", "batch_size", "n_epochs", "torch_threads"):
            if getattr(self, name) < 1:
                raise invalid(f"--{name.replace('_', '-')}", getattr(self, name), ">= 1")
        if not (self.hidden and all(h >= 1 for h in self.hidden)):
            raise invalid("--hidden", self.hidden, "one or more layer widths >= 1")
        if not (0 < self.learning_rate < 1 and 0 < self.gamma <= 1 and self.reward_scale_usd > 0):
            raise invalid(
                "--lr/--gamma/--reward-scale",
                (self.learning_rate, self.gamma, self.reward_scale_usd),
                "0 < lr < 1, 0 < gamma <= 1, reward scale > 0",
            )
        if self.max_env_steps is not None and self.max_env_steps < 1:
            raise invalid("--max-env-steps", self.max_env_steps, ">= 1 or None")


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
    _require_sb3()
    return _adapter_class()(venv, reward_scale)


@dataclass(frozen=True)
class MLPPolicy:
    """The deterministic actor of a PPO ``MlpPolicy``, rebuilt from arrays (no torch, no pickle).

    ``act(obs)``: scale ``clip((obs - mean) / sqrt(var + eps), ±clip)``, the tanh layers,
    the action layer (the Gaussian's mean), clipped to ``[action_low, action_high]``.
    """

    config: dict[str, Any]
    weights: dict[str, np.ndarray]
    name: str = "PPO agent (Stable-Baselines3)"
    _layers: list[tuple[np.ndarray, np.ndarray]] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_layers", _check_shapes(self.config, self.weights))

    def reset(self, info: Any) -> None:
        pass

    def act(self, obs: np.ndarray, info: Any = None) -> np.ndarray:
        c = self.config
        x = np.asarray(obs, dtype=np.float32)
        mean, var = np.asarray(c["obs_mean"]), np.asarray(c["obs_var"])
        x = np.clip((x - mean) / np.sqrt(var + c["obs_epsilon"]), -c["obs_clip"], c["obs_clip"])
        h = x.astype(np.float32)
        for i, (w, b) in enumerate(self._layers):
            h = h @ w.T + b
            if i < len(self._layers) - 1:
                h = np.tanh(h)
        return np.clip(h, c["action_low"], c["action_high"]).astype(np.float32)


def _check_shapes(config: dict[str, Any], weights: dict[str, np.ndarray]) -> list[tuple]:
    """The layers as (weight, bias) pairs; refuses a config whose shapes disagree with them."""
    if config.get("format") != FORMAT:
        raise invalid("policy.json format", config.get("format"), repr(FORMAT))
    dims = [config["obs_dim"], *config["hidden"], config["act_dim"]]
    layers = []
    for i, (n_in, n_out) in enumerate(itertools.pairwise(dims)):
        name = f"layer{i}"
        for key, shape in ((f"{name}.weight", (n_out, n_in)), (f"{name}.bias", (n_out,))):
            if key not in weights:
                raise invalid("policy.npz", sorted(weights), f"an array {key!r} of shape {shape}")
            if weights[key].shape != shape:
                raise invalid(
                    f"policy.npz[{key!r}].shape", weights[key].shape, f"{shape}",
                    f"policy.json: obs_dim={config['obs_dim']}, hidden={config['hidden']}, "
                    f"act_dim={config['act_dim']}",
                )  # fmt: skip
        layers.append((weights[f"{name}.weight"], weights[f"{name}.bias"]))
    extra = sorted(
        set(weights) - {f"layer{i}.{p}" for i in range(len(layers)) for p in ("weight", "bias")}
    )
    if extra:
        raise invalid("policy.npz arrays", extra, f"{len(layers)} layers as policy.json says")
    for key, n in (("obs_mean", dims[0]), ("obs_var", dims[0])):
        if np.shape(config[key]) != (n,):
            raise invalid(f"policy.json {key} shape", np.shape(config[key]), f"({n},) = obs_dim")
    for key in ("action_low", "action_high"):
        if np.shape(config[key]) != (dims[-1],):
            raise invalid(f"policy.json {key} shape", np.shape(config[key]), f"({dims[-1]},)")
    return layers


def save_policy(directory: Path, policy: MLPPolicy) -> None:
    """``policy.npz`` (float32 arrays, no pickle) and ``policy.json`` in ``directory``."""
    directory.mkdir(parents=True, exist_ok=True)
    np.savez(directory / "policy.npz", **policy.weights)
    atomic_write_json(directory / "policy.json", policy.config)


def load_policy(directory: Path | str) -> MLPPolicy:
    """The policy saved by :func:`save_policy`, checked; never unpickles."""
    directory = Path(directory)
    for name in ("policy.json", "policy.npz"):
        if not (directory / name).is_file():
            raise FileNotFoundError(
                f"--policy {str(directory)!r}: no {name} there; train one with "
                "python -m evaluation.control.rl train --out DIR"
            )
    config = json.loads((directory / "policy.json").read_text(encoding="utf-8"))
    with np.load(directory / "policy.npz", allow_pickle=False) as data:
        weights = {k: data[k] for k in data.files}
    return MLPPolicy(config, weights)


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


def train(settings: PPOSettings) -> tuple[MLPPolicy, dict[str, Any]]:
    """PPO on ``settings.envs`` native vector envs until the wall-clock budget (or
    ``max_env_steps``) is spent. Returns the policy and a log (env steps, speed, returns)."""
    _require_sb3()
    import numba
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import VecNormalize

    class Budget(BaseCallback):
        def __init__(self, seconds: float) -> None:
            super().__init__()
            self.seconds, self.rollouts = seconds, []

        def _on_training_start(self) -> None:
            self.t0 = time.perf_counter()

        def _on_step(self) -> bool:
            return time.perf_counter() - self.t0 < self.seconds

        def _on_rollout_end(self) -> None:
            ended = self.training_env.venv.episode_returns
            self.rollouts.append(
                {
                    "env_steps": int(self.num_timesteps),
                    "seconds": round(time.perf_counter() - self.t0, 1),
                    "mean_return_usd_last_episodes": float(np.mean(ended[-20:])) if ended else None,
                }
            )

    s = settings
    with _global_state_kept():
        torch.set_num_threads(s.torch_threads)
        # numba's OpenMP workers spin-wait after each env step and starve torch's forward
        # passes (measured: 12 ms instead of 1 ms per step of 64 envs on two cores)
        numba.set_num_threads(1)
        venv = gym.make_vec(CONTROL_ENV_ID, s.envs, vectorization_mode="vector_entry_point")
        env = VecNormalize(sb3_vec_env(venv, s.reward_scale_usd), norm_reward=False, gamma=s.gamma)
        model = PPO(
            "MlpPolicy", env, n_steps=s.n_steps, batch_size=s.batch_size,
            n_epochs=s.n_epochs, learning_rate=s.learning_rate, gamma=s.gamma,
            policy_kwargs={"net_arch": {"pi": list(s.hidden), "vf": list(s.hidden)}},
            seed=s.seed, device="cpu", verbose=0,
        )  # fmt: skip
        budget = Budget(60.0 * s.minutes)
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


def validate(policy: Any, n_seeds: int, n_steps: int = 3999) -> dict[str, Any]:
    """``policy`` and the best fixed set points on validation seeds 5000.. (each scenario at the
    paper's size and onset), with the control study's harness: mean returns and the gap."""
    seeds = range(VALIDATION_SEED, VALIDATION_SEED + n_seeds)
    scenarios = scenario_names()
    scores = returns.run_study([fixed_setpoints(), policy], seeds, n_steps, scenarios)
    out: dict[str, Any] = {"seeds": list(seeds), "policies": {}}
    for s in returns.summarise(scores, reference=policy.name):
        by = {sc: np.mean([e.return_usd for e in scores if e.policy == s.policy and e.scenario == sc]) for sc in scenarios}  # fmt: skip
        out["policies"][s.policy] = {
            "mean_return_usd": s.return_usd.estimate,
            "trips_per_100": s.trips_per_100,
            "by_scenario": {k: round(float(v), 1) for k, v in by.items()},
        }
    rl, fixed = (out["policies"][p.name]["mean_return_usd"] for p in (policy, fixed_setpoints()))
    out["rl_minus_fixed_usd"] = rl - fixed
    return out


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


def main(argv: Sequence[str] | None = None) -> int:
    parser = command_parser(
        "evaluation.control.rl",
        __doc__ or "",
        (
            ("train --minutes 30 --seed 1000 --out results/rl", "the 30-minute agent"),
            ("evaluate --policy results/rl --seeds 20 --out results/control_rl", "the study"),
        ),
    )
    sub = parser.add_subparsers(dest="command", required=True)
    t = sub.add_parser("train", help="train PPO on the native vector env")
    d = PPOSettings()
    t.add_argument("--minutes", type=float, default=d.minutes, help="wall-clock budget (30)")
    t.add_argument("--envs", type=int, default=d.envs, help=f"vector envs ({d.envs})")
    t.add_argument("--seed", type=int, default=d.seed, help="first training seed (1000)")
    t.add_argument("--n-steps", type=int, default=d.n_steps, help="steps per env per rollout")
    t.add_argument("--batch-size", type=int, default=d.batch_size)
    t.add_argument("--n-epochs", type=int, default=d.n_epochs)
    t.add_argument("--lr", type=float, default=d.learning_rate, help="learning rate")
    t.add_argument("--gamma", type=float, default=d.gamma)
    t.add_argument("--hidden", default="64,64", help="layer widths of actor and critic")
    t.add_argument("--reward-scale", type=float, default=d.reward_scale_usd, help="USD")
    t.add_argument("--max-env-steps", type=int, default=None, help="stop earlier, at this many")
    t.add_argument("--torch-threads", type=int, default=d.torch_threads)
    t.add_argument("--val-seeds", type=int, default=2, help="validation seeds per scenario")
    t.add_argument("--out", type=out_path, required=True)
    e = sub.add_parser("evaluate", help="the saved agent in the control study (test seeds)")
    e.add_argument("--policy", type=Path, required=True, help="a train --out directory")
    e.add_argument("--seeds", type=int, default=20)
    e.add_argument("--steps", type=int, default=3999)
    e.add_argument("--diagnosers", default="", help="supervisors too (as evaluation.control)")
    e.add_argument(
        "--diagnoser-params", default="{}", metavar="JSON", help="as evaluation.control's"
    )
    e.add_argument("--out", type=out_path, default=Path("results/control_rl"))
    return run_command(parser, _run, argv)


def _run(args: argparse.Namespace) -> int:
    if args.command == "evaluate":
        policy = load_policy(args.policy)
        study = ["--seeds", str(args.seeds), "--steps", str(args.steps), "--out", str(args.out)]
        study += ["--diagnosers", args.diagnosers, "--diagnoser-params", args.diagnoser_params]
        return returns.main(study, extra_policies=[policy])
    try:
        hidden = tuple(int(h) for h in args.hidden.split(","))
    except ValueError:
        raise invalid("--hidden", args.hidden, "comma-separated integers, e.g. 64,64") from None
    if args.val_seeds < 0:
        raise invalid("--val-seeds", args.val_seeds, ">= 0")
    settings = PPOSettings(
        minutes=args.minutes, envs=args.envs, seed=args.seed, n_steps=args.n_steps,
        batch_size=args.batch_size, n_epochs=args.n_epochs, learning_rate=args.lr,
        gamma=args.gamma, hidden=hidden, reward_scale_usd=args.reward_scale,
        max_env_steps=args.max_env_steps, torch_threads=args.torch_threads,
    )  # fmt: skip
    check_out_path("--out", args.out)
    _require_sb3()
    policy, log = train(settings)
    save_policy(args.out, policy)
    if args.val_seeds:
        log["validation"] = validate(policy, args.val_seeds)
    atomic_write_json(args.out / "training.json", log)
    print(
        f"{log['env_steps']:,} env steps in {log['seconds']:.0f} s "
        f"({log['env_steps_per_s']:,.0f}/s); wrote {args.out} (policy.npz, policy.json, "
        "training.json)"
    )
    if args.val_seeds:
        print(json.dumps(log["validation"], indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
