"""Speed of the native vector env: ``python -m bench.vector_speed --envs 16,1024 --threads 1,2``.

Prints env-steps per second of :class:`fcc_env.vector_env.FCCVectorEnv` (through
``gym.make_vec(..., vectorization_mode="vector_entry_point", threads=...)``) beside Gymnasium's
``SyncVectorEnv`` over the same keywords, with the native/sync ratio, for ``FCC-v0`` (scenario
f1) and ``FCC-closedloop-v0``, random actions, the registered time limit, at each number of envs
and threads asked (``auto``: the env's default policy, :func:`fcc_env.vector_threads.vector_threads`).
Each figure is by wall clock and by the CPU time of this process (``time.process_time``, every
thread counted: threads spinning at a barrier show there); with ``--repeats`` above 1, the
median and the range (min-max) of the runs, measured in turn. Figures, not assertions: the machine
may be shared (the wall figures then depend on its load), so run it more than once.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from typing import Any

import gymnasium as gym
import numba
import numpy as np

import fcc_env
from fcc_common.invocation import command_parser, csv_list, run_command
from fcc_env.simulation import check_memory
from fcc_env.vector_env import RING
from fcc_env.vector_threads import vector_threads

#: The issues' goals (45): at 1024 envs >= 20x sync and at 16 envs >= 1x sync; native >= 500,000
#: env-steps/s at 1024 envs on a free machine (issue 24).
NATIVE_GOAL = 500_000
SPEEDUP_GOAL = 20.0
AUTO = "auto"


def bench(envs: gym.vector.VectorEnv, n_steps: int, seed: int = 0) -> tuple[float, float]:
    """(wall, CPU) env-steps/s of ``n_steps`` vector steps of random actions (after a short
    warm-up)."""
    rng = np.random.default_rng(seed)
    envs.reset(seed=seed)
    shape = envs.action_space.shape
    for _ in range(3):  # warm-up: the compiled kernels' cache load, first-call overheads
        envs.step(rng.uniform(-1, 1, shape).astype(np.float32))
    actions = rng.uniform(-1, 1, (n_steps, *shape)).astype(np.float32)
    wall, cpu = time.perf_counter(), time.process_time()
    for a in actions:
        envs.step(a)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    n = n_steps * envs.num_envs
    return n / wall, n / max(cpu, 1e-9)


def run(env_id: str, n_envs: int, n_steps: int, mode: str, **kwargs: Any) -> tuple[float, float]:
    """(wall, CPU) env-steps/s of ``n_envs`` envs of ``env_id`` in ``mode`` (``"sync"`` or
    ``"vector_entry_point"``; ``kwargs`` to ``gym.make_vec``)."""
    envs = gym.make_vec(env_id, n_envs, vectorization_mode=mode, **kwargs)
    try:
        return bench(envs, n_steps)
    finally:
        envs.close()


def summary(values: list[float], fmt: str = ",.0f") -> str:
    """The value, or ``median [min-max]`` of several."""
    if len(values) == 1:
        return f"{values[0]:{fmt}}"
    return f"{statistics.median(values):{fmt}} [{min(values):{fmt}}-{max(values):{fmt}}]"


def main(argv: list[str] | None = None) -> int:
    ap = command_parser(
        "bench.vector_speed",
        __doc__ or "",
        (
            ("", "1024 envs, the default threads: the native vector env against sync, both ids"),
            (
                "--envs 16,64,256,1024 --threads 1,2,auto --repeats 3",
                "the thread policy's table (lab/env-speed.md)",
            ),
            ("--envs 256 --steps 500 --threads 1", "a quick look on one thread"),
        ),
    )
    ap.add_argument("--envs", type=csv_list, default=("1024",), help="envs per vector env")
    ap.add_argument("--steps", type=int, default=1000, help="vector steps of the native env")
    ap.add_argument(
        "--sync-steps", type=int, default=20, help="vector steps of SyncVectorEnv (slow)"
    )
    ap.add_argument(
        "--threads",
        type=csv_list,
        default=(AUTO,),
        help="numba threads of the native env, a list; 'auto': the env's default policy",
    )
    ap.add_argument("--repeats", type=int, default=1, help="runs of each setting")
    return run_command(ap, lambda args: _report(args, ap), argv)


def _integers(ap: argparse.ArgumentParser, flag: str, items: tuple[str, ...]) -> list[int | None]:
    """The items of a list flag as integers (``auto`` as None)."""
    out: list[int | None] = []
    for item in items:
        if flag == "--threads" and item == AUTO:
            out.append(None)
            continue
        try:
            out.append(int(item))
        except ValueError:
            ap.error(f"{flag} {item!r} is not an integer")
    return out


def _report(args: argparse.Namespace, ap: argparse.ArgumentParser) -> int:
    """The work of :func:`main`: its failures (and a Ctrl-C) are reported by :func:`run_command`."""
    envs = _integers(ap, "--envs", args.envs)
    threads = _integers(ap, "--threads", args.threads)
    limits = [("--envs", v, 1) for v in envs]
    limits += [("--steps", args.steps, 1), ("--sync-steps", args.sync_steps, 1)]
    limits += [("--repeats", args.repeats, 1)] + [("--threads", t, 1) for t in threads if t]
    for flag, value, low in limits:
        if value < low:
            ap.error(f"{flag} {value} is outside the allowed range: an integer >= {low}")
    pool = numba.config.NUMBA_NUM_THREADS
    for t in threads:
        if t is not None and t > pool:
            ap.error(
                f"--threads {t} is outside the allowed range: 1..{pool} (numba's thread pool "
                "on this machine, NUMBA_NUM_THREADS)"
            )
    for n in envs:
        try:  # each env holds its streams of RING samples (measured: 152 KiB per env, under
            # half of what a simulated batch of RING samples holds, which the budget counts)
            check_memory(n, RING)
        except ValueError as e:
            raise ValueError(f"--envs {n}: {e}") from None
    print(
        f"native {args.steps} steps, sync {args.sync_steps} steps, {args.repeats} repeat(s); "
        f"numba pool {pool} threads, threading layer setting {numba.config.THREADING_LAYER!r}, "
        f"OMP_WAIT_POLICY={os.environ.get('OMP_WAIT_POLICY')}; env-steps/s (x sync)"
    )
    for env_id, kwargs in ((fcc_env.ENV_ID, {"scenario": "f1"}), (fcc_env.CLOSED_LOOP_ENV_ID, {})):
        _table(env_id, kwargs, envs, threads, args)
    print(f"goals: >= {SPEEDUP_GOAL:.0f}x sync at 1024 envs, >= 1x at 16 (issue 45)")
    try:
        print(f"numba threading layer used: {numba.threading_layer()}")
    except ValueError:  # no parallel kernel ran (every setting on one thread)
        print("numba threading layer used: none (every run serial)")
    return 0


def _table(
    env_id: str, kwargs: dict[str, Any], envs: list[int], threads: list[int | None], args: Any
) -> None:
    """One env id's table: a row per number of envs, a column pair per thread setting."""
    names = [AUTO if t is None else str(t) for t in threads]
    print(f"\n{env_id}")
    head = " | ".join(f"threads {n} wall | threads {n} CPU" for n in names)
    print(f"| envs | sync wall | sync CPU | {head} |")
    print("|---" * (3 + 2 * len(threads)) + "|")
    for n in envs:
        sync: dict[str, list[float]] = {"wall": [], "cpu": []}
        native = {t: {"wall": [], "cpu": []} for t in names}
        for _ in range(args.repeats):  # in turn, so that a change of load falls on every setting
            got = run(env_id, n, args.sync_steps, "sync", **kwargs)
            for clock, v in zip(("wall", "cpu"), got, strict=True):
                sync[clock].append(v)
            for t, name in zip(threads, names, strict=True):
                got = run(env_id, n, args.steps, "vector_entry_point", threads=t, **kwargs)
                for clock, v in zip(("wall", "cpu"), got, strict=True):
                    native[name][clock].append(v)
        cells = [summary(sync["wall"]), summary(sync["cpu"])]
        for name in names:
            for clock in ("wall", "cpu"):
                ratio = statistics.median(native[name][clock]) / statistics.median(sync[clock])
                cells.append(f"{summary(native[name][clock])} ({ratio:.1f}x)")
        auto = f" (auto: {vector_threads(n)})" if AUTO in names else ""
        print(f"| {n}{auto} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    raise SystemExit(main())
