"""Speed of the native vector env: ``python -m bench.vector_speed --envs 1024 --steps 2000``.

Prints env-steps per second of :class:`fcc_env.vector_env.FCCVectorEnv` and of Gymnasium's
``SyncVectorEnv`` over the same keywords, side by side with their ratio, for ``FCC-v0``
(scenario f1) and ``FCC-closedloop-v0``, random actions, the registered time limit. Figures,
not assertions: the machine may be shared, so run it more than once. The native env meets
every step at a parallel barrier, where numba's OpenMP threads spin: on a machine whose cores
are busy with other work, ``OMP_WAIT_POLICY=PASSIVE`` in the environment (or ``--threads 1``)
runs it several times faster.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import gymnasium as gym
import numba
import numpy as np

import fcc_env
from fcc_common.invocation import command_parser, run_command
from fcc_env.simulation import check_memory
from fcc_env.vector_env import RING

#: The issue's goals at 1024 envs: env-steps/s of the native env, and its speed-up over sync.
NATIVE_GOAL = 500_000
SPEEDUP_GOAL = 20.0


def bench(envs: gym.vector.VectorEnv, n_steps: int, seed: int = 0) -> float:
    """Env-steps/s of ``n_steps`` vector steps of random actions (after a short warm-up)."""
    rng = np.random.default_rng(seed)
    envs.reset(seed=seed)
    shape = envs.action_space.shape
    for _ in range(3):  # warm-up: the compiled kernels' cache load, first-call overheads
        envs.step(rng.uniform(-1, 1, shape).astype(np.float32))
    actions = rng.uniform(-1, 1, (n_steps, *shape)).astype(np.float32)
    t0 = time.perf_counter()
    for a in actions:
        envs.step(a)
    return n_steps * envs.num_envs / (time.perf_counter() - t0)


def compare(env_id: str, n_envs: int, n_steps: int, sync_steps: int, **kwargs: Any) -> tuple:
    """(native, sync) env-steps/s of ``env_id`` with ``n_envs`` envs."""
    native = gym.make_vec(env_id, n_envs, vectorization_mode="vector_entry_point", **kwargs)
    sync = gym.make_vec(env_id, n_envs, vectorization_mode="sync", **kwargs)
    try:
        return bench(native, n_steps), bench(sync, sync_steps)
    finally:
        native.close()
        sync.close()


def main(argv: list[str] | None = None) -> int:
    ap = command_parser(
        "bench.vector_speed",
        __doc__ or "",
        (
            ("", "1024 envs: the native vector env against SyncVectorEnv, both ids"),
            ("--envs 256 --steps 500 --threads 1", "a quick look on one thread"),
        ),
    )
    ap.add_argument("--envs", type=int, default=1024, help="envs per vector env")
    ap.add_argument("--steps", type=int, default=1000, help="vector steps of the native env")
    ap.add_argument(
        "--sync-steps", type=int, default=20, help="vector steps of SyncVectorEnv (slow)"
    )
    ap.add_argument(
        "--threads", type=int, default=None, help="numba threads of the native env (default: all)"
    )
    return run_command(ap, lambda args: _report(args, ap), argv)


def _report(args: argparse.Namespace, ap: argparse.ArgumentParser) -> int:
    """The work of :func:`main`: its failures (and a Ctrl-C) are reported by :func:`run_command`."""
    limits = {
        "--envs": (args.envs, 1),
        "--steps": (args.steps, 1),
        "--sync-steps": (args.sync_steps, 1),
    }
    limits["--threads"] = (args.threads if args.threads is not None else 1, 1)
    for flag, (value, low) in limits.items():
        if value < low:
            ap.error(f"{flag} {value} is outside the allowed range: an integer >= {low}")
    if args.threads is not None and args.threads > numba.config.NUMBA_NUM_THREADS:
        ap.error(
            f"--threads {args.threads} is outside the allowed range: 1.."
            f"{numba.config.NUMBA_NUM_THREADS} (numba's thread pool on this machine)"
        )
    try:  # each env holds its streams of RING samples (measured: 152 KiB per env, under half
        # of what a simulated batch of RING samples holds, which the budget counts)
        check_memory(args.envs, RING)
    except ValueError as e:
        raise ValueError(f"--envs {args.envs}: {e}") from None
    if args.threads is not None:
        numba.set_num_threads(args.threads)
    print(
        f"{args.envs} envs; native {args.steps} steps on {numba.get_num_threads()} numba "
        f"thread(s), sync {args.sync_steps} steps"
    )
    print(f"{'env id':<20} {'native steps/s':>15} {'sync steps/s':>13} {'ratio':>7}")
    for env_id, kwargs in ((fcc_env.ENV_ID, {"scenario": "f1"}), (fcc_env.CLOSED_LOOP_ENV_ID, {})):
        native, sync = compare(env_id, args.envs, args.steps, args.sync_steps, **kwargs)
        print(f"{env_id:<20} {native:>15,.0f} {sync:>13,.0f} {native / sync:>6.1f}x")
    print(f"goals: native >= {NATIVE_GOAL:,} env-steps/s, >= {SPEEDUP_GOAL:.0f}x sync")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
