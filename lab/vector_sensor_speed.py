"""CPU seconds per 10,000 env steps of ``FCC-control-v0``: native vector env against
``SyncVectorEnv``, on the sensor catalogue's draws (lab/control-catalogue.md, 2026-12-07).

Steps ``--envs`` envs (training seeds 1000..) with uniform random actions for ``--steps``
vector steps after a warm-up of 50 (compilation out of the figure), and prints the CPU time of
this process (``time.process_time``) per 10,000 env steps for each of: native
``catalogue="sensor"``, sync ``catalogue="sensor"``, native ``catalogue="paper"``, sync
``catalogue="all"``. Figures, not assertions: the machine may be shared (quote the load).

    python lab/vector_sensor_speed.py --envs 16 --steps 1000
"""

from __future__ import annotations

import argparse
import os
import time

import gymnasium as gym
import numpy as np

import fcc_env

CASES = (
    ("vector_entry_point", "sensor"),
    ("sync", "sensor"),
    ("vector_entry_point", "paper"),
    ("sync", "all"),
)


def cpu_per_10k(mode: str, catalogue: str, n_envs: int, steps: int) -> float:
    """CPU seconds per 10,000 env steps of ``steps`` vector steps (after 50 of warm-up)."""
    envs = gym.make_vec(
        fcc_env.CONTROL_ENV_ID, n_envs, vectorization_mode=mode, catalogue=catalogue
    )
    envs.reset(seed=1000)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1.0, 1.0, (steps + 50, n_envs, 2))
    for a in actions[:50]:
        envs.step(a)
    t0 = time.process_time()
    for a in actions[50:]:
        envs.step(a)
    cpu = time.process_time() - t0
    envs.close()
    return cpu / (steps * n_envs) * 10_000


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--envs", type=int, default=16)
    ap.add_argument("--steps", type=int, default=1000, help="vector steps per case")
    a = ap.parse_args()
    print(f"load average {os.getloadavg()}; {a.envs} envs x {a.steps} steps")
    for mode, catalogue in CASES:
        s = cpu_per_10k(mode, catalogue, a.envs, a.steps)
        print(f"{mode:>18} catalogue={catalogue:<6} {s:6.3f} CPU s per 10k env steps")


if __name__ == "__main__":
    main()
