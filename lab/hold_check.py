"""The sensor-correcting supervisor's hold of a frozen loop without set-point room, on and off.

On the six loop-sensor faults (each at its default size, onset 2000) of validation seeds, runs
``SensorCorrectingSupervisor`` with ``hold_frozen`` on; where the hold never fired in an episode
the policy with it off acts identically (the hold is the only difference), so that episode's
"off" return is the "on" one and only the episodes where it fired are run again. With
``--ppo DIR`` it also runs, on a stuck T_rx only, the saved PPO agent and
``ppo+sensor-correcting`` with the hold on and off (does the hold beat the agent on the loop
the supervisor could not rebuild?). Prints per scenario the means, the paired differences with
95 % bootstrap intervals and the trips (lab/control-catalogue.md, 2026-12-07 evening).

    python lab/hold_check.py --first 5320 --n 20 --ppo /tmp/ppoinfo/ppo_sensor --out /tmp/ppoinfo/hold.jsonl
    python lab/hold_check.py --report /tmp/ppoinfo/hold.jsonl
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import fcc_env  # noqa: F401 (registers the envs)
from evaluation.control.policy_registry import make_policy
from evaluation.metrics.intervals import bootstrap_ci

# ``python lab/<script>.py`` puts lab/ first on the path, not the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lab.control_catalogue import LOOP_SENSOR_SCENARIOS


def episode(policy, scenario: str, channel: str, seed: int, steps: int = 3999) -> dict:
    env = gym.make("FCC-control-v0", scenario=scenario, fault_channel=channel)
    obs, info = env.reset(seed=seed)
    policy.reset(info)
    sup = getattr(policy, "supervisor", policy)
    total, tripped, held = 0.0, False, False
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(policy.act(obs, info))
        held = held or bool(getattr(sup, "_held", np.zeros(2)).any())
        total += float(reward)
        if terminated or truncated:
            tripped = bool(terminated)
            break
    env.close()
    return {"return": total, "trip": tripped, "held": held}


def run(first: int, n: int, out: str, ppo: str | None) -> None:
    on = make_policy("sensor-correcting")
    off = make_policy("sensor-correcting", hold_frozen=False, soft_sensor=on.soft_sensor)
    extra = {}
    if ppo:
        extra = {
            "ppo": make_policy("ppo", directory=ppo),
            "hybrid": make_policy(
                "ppo+sensor-correcting",
                directory=ppo,
                soft_sensor=on.soft_sensor,
                hold_frozen=True,
            ),
            "hybrid-nohold": make_policy(
                "ppo+sensor-correcting",
                directory=ppo,
                soft_sensor=on.soft_sensor,
                hold_frozen=False,
            ),
        }
    with open(out, "w") as f:
        for seed in range(first, first + n):
            for scenario, channel in LOOP_SENSOR_SCENARIOS:
                t0 = time.process_time()
                row = {"seed": seed, "scenario": scenario, "channel": channel}
                row["on"] = episode(on, scenario, channel, seed)
                row["off"] = (
                    episode(off, scenario, channel, seed) if row["on"]["held"] else row["on"]
                )
                if scenario == "sensor-stuck" and channel == "T_rx":
                    for key, policy in extra.items():
                        row[key] = episode(policy, scenario, channel, seed)
                row["cpu_s"] = round(time.process_time() - t0, 2)
                f.write(json.dumps(row) + "\n")
                f.flush()


def _ci(values) -> str:
    iv = bootstrap_ci(list(values))
    return f"{iv.estimate:,.0f} [{iv.low:,.0f}, {iv.high:,.0f}]"


def report(paths: list[str]) -> None:
    rows = [json.loads(line) for p in paths for line in open(p)]
    print("| scenario | n | hold on | hold off | on − off (paired) | held in | trips on/off |")
    print("|---|---|---|---|---|---|---|")
    for scenario, channel in LOOP_SENSOR_SCENARIOS:
        g = [r for r in rows if r["scenario"] == scenario and r["channel"] == channel]
        if not g:
            continue
        on, off = (np.array([r[k]["return"] for r in g]) for k in ("on", "off"))
        trips = "/".join(str(sum(r[k]["trip"] for r in g)) for k in ("on", "off"))
        held = sum(r["on"]["held"] for r in g)
        print(
            f"| {scenario} {channel} | {len(g)} | {_ci(on)} | {_ci(off)} | {_ci(on - off)} "
            f"| {held} | {trips} |"
        )
    g = [r for r in rows if "ppo" in r]
    if g:
        print("\nstuck T_rx: | policy | mean | − ppo (paired) | trips |")
        agent = np.array([r["ppo"]["return"] for r in g])
        for key in ("ppo", "hybrid", "hybrid-nohold", "on"):
            x = np.array([r[key]["return"] for r in g])
            trips = sum(r[key]["trip"] for r in g)
            print(f"| {key} | {_ci(x)} | {_ci(x - agent)} | {trips}/{len(g)} |")
    print(f"\n{len(rows)} rows, {sum(r['cpu_s'] for r in rows):.0f} CPU s")


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--first", type=int, default=5320)
    ap.add_argument("--n", type=int, default=20)
    ap.add_argument("--ppo", default=None, help="a saved PPO agent: ppo and the hybrid too")
    ap.add_argument("--out", default="/tmp/hold_check.jsonl")
    ap.add_argument("--report", nargs="*")
    a = ap.parse_args()
    if a.report:
        report(a.report)
    elif a.first < 5000:
        raise SystemExit(f"--first {a.first}: validation seeds only (5000..)")
    else:
        run(a.first, a.n, a.out, a.ppo)
