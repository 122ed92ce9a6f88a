"""Stored reference of ``FCC-control-v0``'s reward: ``python tests/control_reference.py``.

Writes ``tests/data/control-reward-reference.npz``: the inputs that the reward reads (``state``,
``inputs``, ``X``, ``coke_make``, ``controller_saturated``, ``terminated``) and the reward and
its terms that ``FCCControlEnv.step`` returned for them, before the single-env reward took its
scalar path (issue 44, item 5). The test feeds the stored inputs to today's code and asks for
the stored numbers bit for bit: the check is pure IEEE arithmetic, so it holds on any machine,
unlike a stored plant trajectory (compiled kernels and libm may differ in the last bit).

The rows are steps of fixed-seed rollouts (every scenario, actions past the ±1 limits so that
clipping and controller saturation occur) and the same rows pushed into every constraint
region, with and without a trip, under the default and a tight :class:`EconomicReward`.
Regenerate only for an intended change of the reward, and say so in the commit.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import fcc_env
from fcc_env.control_task import REWARD_TERMS, EconomicReward

REFERENCE = Path(__file__).resolve().parent / "data" / "control-reward-reference.npz"
#: The economics of the rows: the defaults, and limits tight enough that every constraint
#: term is non-zero somewhere in a rollout.
ECONOMICS = (
    EconomicReward(),
    EconomicReward(regenerator_max_C=700.0, regenerator_min_C=690.0, well_min_t=30.0),
)
SCENARIOS = ("nominal", "f1", "f2", "f3", "f4", "sensor-bias")
STEPS = 60
DT_S = 10.0


def rollout_rows(scenario: str, seed: int) -> dict[str, np.ndarray]:
    """The reward's inputs over ``STEPS`` steps of ``FCC-control-v0`` (actions in ±1.5)."""
    env = gym.make(fcc_env.CONTROL_ENV_ID, scenario=scenario, fault_time=20)
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    rows: dict[str, list[Any]] = {k: [] for k in ("state", "inputs", "X", "coke_make", "sat")}
    rows["terminated"] = []
    for _ in range(STEPS):
        _, _, terminated, _, info = env.step(rng.uniform(-1.5, 1.5, 2).astype(np.float32))
        rows["state"].append(info["state"])
        rows["inputs"].append(info["inputs"])
        rows["X"].append(info["X"])
        rows["coke_make"].append(info["coke_make"])
        rows["sat"].append(info["controller_saturated"])
        rows["terminated"].append(terminated)
    env.close()
    return {k: np.array(v) for k, v in rows.items()}


def reference_rows() -> dict[str, np.ndarray]:
    """Rollout rows, then the same rows pushed into the constraint regions with a trip."""
    parts = [rollout_rows(s, 1000 + i) for i, s in enumerate(SCENARIOS)]
    rows = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    pushed = {k: v.copy() for k, v in rows.items()}
    rng = np.random.default_rng(1)
    n = len(pushed["X"])
    pushed["state"][:, 9] += rng.uniform(0.0, 80.0, n)  # T_d1: afterburn over the warning
    pushed["state"][:, 7] += rng.uniform(-50.0, 50.0, n)  # T_rg2 about its limit
    pushed["state"][:, 4] -= rng.uniform(0.0, 80.0, n)  # T_rg1 under its limit
    pushed["state"][:, 8] *= rng.uniform(0.1, 1.0, n)  # the well drained
    pushed["sat"] = rng.random(n) < 0.5
    pushed["terminated"] = rng.random(n) < 0.5
    return {k: np.concatenate([rows[k], pushed[k]]) for k in rows}


def step_info(rows: dict[str, np.ndarray], i: int) -> dict[str, Any]:
    """Row ``i`` as the env's info holds it (``X`` and ``coke_make`` floats, the flag a bool)."""
    return {
        "state": rows["state"][i].copy(),
        "inputs": rows["inputs"][i].copy(),
        "X": float(rows["X"][i]),
        "coke_make": float(rows["coke_make"][i]),
        "controller_saturated": bool(rows["sat"][i]),
    }


def main() -> None:
    from fcc_env.control_task import reward_terms, total_reward

    rows = reference_rows()
    n = len(rows["X"])
    terms = np.empty((len(ECONOMICS), n, len(REWARD_TERMS)))
    reward = np.empty((len(ECONOMICS), n))
    for j, e in enumerate(ECONOMICS):
        for i in range(n):
            t = reward_terms(step_info(rows, i), bool(rows["terminated"][i]), e, DT_S)
            terms[j, i] = list(t.values())
            reward[j, i] = float(total_reward(t))
    REFERENCE.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(REFERENCE, **rows, terms=terms, reward=reward)
    print(f"wrote {REFERENCE} ({n} rows x {len(ECONOMICS)} economics)")


if __name__ == "__main__":
    main()
