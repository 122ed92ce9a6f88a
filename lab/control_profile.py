"""Where a step of ``FCC-control-v0`` spends its time: ``python lab/control_profile.py``.

cProfile over ``--steps`` steps of one ``gym.make("FCC-control-v0", scenario="f1")`` env (zero
actions, the registered wrappers), then the functions by own time and the step's cumulative
split between the plant (``FCCEnv.step``) and the reward (``reward_terms`` and the sum). Issue 44
item 5; the record is lab/env-speed.md. Public API only.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats

import gymnasium as gym
import numpy as np

import fcc_env


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    ap.add_argument("--steps", type=int, default=3000, help="profiled steps (3000)")
    ap.add_argument("--top", type=int, default=20, help="functions listed (20)")
    args = ap.parse_args()
    if not 1 <= args.steps <= 1_000_000 or not 1 <= args.top <= 1000:
        ap.error(f"--steps {args.steps} / --top {args.top}: 1..1000000 / 1..1000")
    env = gym.make(fcc_env.CONTROL_ENV_ID, scenario="f1")
    action = np.zeros(2, np.float32)
    env.reset(seed=1000)
    for _ in range(200):  # warm-up: the compiled kernels' cache load
        env.step(action)
    profile = cProfile.Profile()
    profile.enable()
    for _ in range(args.steps):
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    profile.disable()
    stats = pstats.Stats(profile)
    stats.sort_stats("tottime").print_stats(args.top)
    total = plant = reward = 0.0
    for (path, _, name), (_, _, _, cum, _) in stats.stats.items():  # type: ignore[attr-defined]
        if path.endswith("control_task.py") and name == "step":
            total = cum
        elif path.endswith("env.py") and name == "step" and "fcc_env" in path:
            plant = cum
        elif path.endswith("control_task.py") and name == "reward_terms":
            reward = cum
    print(
        f"FCCControlEnv.step {1e6 * total / args.steps:.1f} µs/step under the profiler: plant "
        f"{1e6 * plant / args.steps:.1f}, reward_terms {1e6 * reward / args.steps:.1f}"
    )


if __name__ == "__main__":
    main()
