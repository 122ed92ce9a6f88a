"""Speed of the control task beside its plant: ``python -m bench.control_speed``.

Prints the single-env steps/s of ``FCC-control-v0`` and of ``FCC-closedloop-v0`` (the same plant
without the reward) through ``gymnasium.make`` with its default wrappers, scenario f1, a fixed
sequence of random actions, and their ratio (issue 44's goal: control/closed-loop >= 0.8 in the
same run). The two are measured in alternation, ``--repeats`` times each, the order swapped every
repeat, so that a change of the machine's load falls on both; each figure is the median over the
repeats with its range (min-max), by wall clock and by CPU time of this process
(``time.process_time``), which a shared machine's other work does not count. The ratio is taken
per repeat (a pair of runs next to each other). Figures, not assertions.
"""

from __future__ import annotations

import argparse
import statistics
import time

import gymnasium as gym
import numpy as np

import fcc_env
from fcc_common.invocation import command_parser, run_command
from fcc_common.validation import Integer, check

#: Issue 44's goal: FCC-control-v0's steps/s over FCC-closedloop-v0's, in the same run.
CONTROL_SPEED_GOAL = 0.8
ENV_IDS = (fcc_env.CONTROL_ENV_ID, fcc_env.CLOSED_LOOP_ENV_ID)


def steps_per_s(env: gym.Env, actions: np.ndarray) -> tuple[float, float]:
    """(wall, CPU) steps/s of ``env`` over ``actions`` (one step each; a reset on an episode end
    counts in the time, not as a step)."""
    env.reset(seed=1000)
    wall0, cpu0 = time.perf_counter(), time.process_time()
    for a in actions:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    return len(actions) / wall, len(actions) / max(cpu, 1e-9)


def measure(n_steps: int, repeats: int) -> dict[str, dict[str, list[float]]]:
    """Per env id: ``wall`` and ``cpu`` steps/s of each repeat, measured in alternation."""
    envs = {i: gym.make(i, scenario="f1") for i in ENV_IDS}
    actions = np.random.default_rng(1000).uniform(-1, 1, (n_steps, 2)).astype(np.float32)
    for env in envs.values():  # warm-up: the compiled kernels' cache load, first-call overheads
        steps_per_s(env, actions[:200])
    out = {i: {"wall": [], "cpu": []} for i in ENV_IDS}
    for r in range(repeats):
        for env_id in ENV_IDS if r % 2 == 0 else ENV_IDS[::-1]:
            wall, cpu = steps_per_s(envs[env_id], actions)
            out[env_id]["wall"].append(wall)
            out[env_id]["cpu"].append(cpu)
    for env in envs.values():
        env.close()
    return out


def summary(values: list[float], fmt: str = ",.0f") -> str:
    """``median [min-max]`` of ``values``."""
    return f"{statistics.median(values):{fmt}} [{min(values):{fmt}}-{max(values):{fmt}}]"


def main(argv: list[str] | None = None) -> int:
    parser = command_parser(
        "bench.control_speed",
        __doc__ or "",
        (
            ("", "7 repeats of 4000 steps per env"),
            ("--steps 1000 --repeats 3", "a quick look"),
        ),
    )
    parser.add_argument("--steps", type=int, default=4000, help="steps per run (4000)")
    parser.add_argument("--repeats", type=int, default=7, help="runs per env (7)")
    return run_command(parser, _report, argv)


def _report(args: argparse.Namespace) -> int:
    """The work of :func:`main`: its failures (and a Ctrl-C) are reported by :func:`run_command`."""
    check("--steps", args.steps, Integer(1, 1_000_000, why="about 3 min at 5,000 steps/s"))
    check("--repeats", args.repeats, Integer(1, 100))
    runs = measure(args.steps, args.repeats)
    ctl, closed = (runs[i] for i in ENV_IDS)
    print(f"{args.repeats} repeats of {args.steps} steps, scenario f1; median [min-max]")
    print("| measure | FCC-control-v0 | FCC-closedloop-v0 | control/closed-loop |")
    print("|---|---|---|---|")
    for clock in ("wall", "cpu"):
        ratios = [a / b for a, b in zip(ctl[clock], closed[clock], strict=True)]
        print(
            f"| steps/s ({clock}) | {summary(ctl[clock])} | {summary(closed[clock])} | "
            f"{summary(ratios, '.2f')} |"
        )
    for clock in ("wall", "cpu"):
        print(
            f"| µs/step ({clock}) | {summary([1e6 / v for v in ctl[clock]], '.1f')} | "
            f"{summary([1e6 / v for v in closed[clock]], '.1f')} | |"
        )
    print(f"goal: control/closed-loop >= {CONTROL_SPEED_GOAL}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
