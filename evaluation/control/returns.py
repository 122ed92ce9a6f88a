"""``python -m evaluation.control``: the control task's baselines on test seeds, with intervals.

Each policy (:mod:`evaluation.control.policies`) runs ``FCC-control-v0`` on the same episodes:
the healthy plant and each fault at the paper's size and onset, ``--seeds`` test seeds each
(seeds 0.., the benchmark's test range; nothing here is tuned, the set points come from the
steady-state search). Per policy: the mean return per episode (USD) with its 95 % bootstrap
interval, trips per 100 episodes, the share of samples inside a constraint region (any penalty
term but the trip below zero), and the loss against the oracle (its return minus the
policy's, paired by episode, with its interval). Written to ``--out`` as ``control.csv`` and
``control.json``; the table is printed.

``--diagnosers`` (default ``pca``) adds a diagnosis-driven supervisor per registered diagnoser
(:class:`~evaluation.control.policies.DiagnosisSupervisor`), trained on episodes of the training
seeds (1000..) run at its healthy set points (healthy, and for an isolator each fault at the
paper's size too):
what its alarms and diagnoses are worth in money and trips. A reinforcement-learning agent joins
the table through ``python -m evaluation.control.rl evaluate`` (:mod:`evaluation.control.rl`).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from diagnosers.bank.relation_cache import shared_relations
from diagnosers.episode.record import Episode
from evaluation.control.figures import episode_figure
from evaluation.control.policies import (
    ARM_AFTER,
    DiagnosisSupervisor,
    Policy,
    ProgramPolicy,
    fault_setpoints,
    fixed_setpoints,
    oracle,
)
from evaluation.metrics.intervals import Interval, bootstrap_ci
from fcc_common.invocation import check_out_path, command_parser, out_path, run_command
from fcc_common.io import atomic_write, atomic_write_json
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.control_task import CONTROL_ENV_ID, REWARD_TERMS
from fcc_env.plant import PlantConfig
from fcc_env.scenarios import fault_names, scenario_names

__all__ = [
    "EpisodeScore",
    "PolicySummary",
    "operated_episodes",
    "run_episode",
    "run_study",
    "summarise",
    "supervisor",
]

#: Training episodes of a supervisor's diagnoser: seeds 1000.. (never a test seed).
TRAIN_SEEDS = range(1000, 1009)

#: The penalty terms whose being below zero marks a sample inside a constraint region.
_CONSTRAINTS = tuple(t for t in REWARD_TERMS if t not in ("conversion", "coke", "air", "trip"))


@dataclass(frozen=True)
class EpisodeScore:
    """One episode of one policy."""

    policy: str
    scenario: str
    seed: int
    return_usd: float
    tripped: bool
    constraint_share: float
    n_steps: int


@dataclass(frozen=True)
class PolicySummary:
    """A policy over the study's episodes."""

    policy: str
    n_episodes: int
    return_usd: Interval
    trips_per_100: float
    constraint_share: float
    loss_vs_oracle_usd: Interval


def run_episode(
    policy: Policy,
    scenario: str,
    seed: int,
    n_steps: int,
    *,
    trace: dict[str, list[Any]] | None = None,
    **env_kwargs: Any,
) -> EpisodeScore:
    """``policy`` on one ``FCC-control-v0`` episode (``scenario`` at its paper size). ``trace``:
    a dict that gets, per step, the reward, the set points, the state and the fault onset
    (``"reward"``, ``"setpoints"``, ``"state"``; ``"onset"`` once) for a figure."""
    env = gym.make(CONTROL_ENV_ID, scenario=scenario, **env_kwargs)
    obs, info = env.reset(seed=seed)
    policy.reset(info)
    if trace is not None:
        trace["onset"] = [info.get("fault_time")]
    total, inside, tripped, k = 0.0, 0, False, 0
    for k in range(1, n_steps + 1):  # noqa: B007 (k is the episode's length after the loop)
        obs, reward, terminated, truncated, info = env.step(policy.act(obs, info))
        total += float(reward)
        inside += any(info["reward_terms"][t] < 0.0 for t in _CONSTRAINTS)
        if trace is not None:
            for key, value in (("reward", reward), ("setpoints", info["setpoints"])):
                trace.setdefault(key, []).append(np.copy(value))
            trace.setdefault("state", []).append(info["state"].copy())
        if terminated or truncated:
            tripped = bool(terminated)
            break
    env.close()
    return EpisodeScore(policy.name, scenario, seed, total, tripped, inside / k, k)


def summarise(scores: Sequence[EpisodeScore], reference: str) -> list[PolicySummary]:
    """Per policy: the mean return, trips, constraint share and the paired loss against the
    policy named ``reference`` (same scenario and seed)."""
    ref = {(s.scenario, s.seed): s.return_usd for s in scores if s.policy == reference}
    out = []
    for name in dict.fromkeys(s.policy for s in scores):
        mine = [s for s in scores if s.policy == name]
        loss = [
            ref[(s.scenario, s.seed)] - s.return_usd for s in mine if (s.scenario, s.seed) in ref
        ]
        out.append(
            PolicySummary(
                name,
                len(mine),
                bootstrap_ci([s.return_usd for s in mine]),
                100.0 * sum(s.tripped for s in mine) / len(mine),
                float(np.mean([s.constraint_share for s in mine])),
                bootstrap_ci(loss) if loss else Interval(math.nan, math.nan, math.nan, 0),
            )
        )
    return out


def run_study(
    policies: Sequence[Policy], seeds: Sequence[int], n_steps: int, scenarios: Sequence[str]
) -> list[EpisodeScore]:
    return [
        run_episode(p, sc, seed, n_steps) for p in policies for sc in scenarios for seed in seeds
    ]


def operated_episodes(
    policy: Policy, scenario: str, seeds: Sequence[int], n_steps: int
) -> list[Episode]:
    """``FCC-control-v0`` episodes run by ``policy``, as the diagnoser of a supervisor sees them
    (its training data must come from the operation it will monitor)."""
    out = []
    for seed in seeds:
        env = gym.make(CONTROL_ENV_ID, scenario=scenario)
        obs, info = env.reset(seed=seed)
        policy.reset(info)
        rows = [obs]
        for _ in range(n_steps):
            obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
            rows.append(obs)
            if terminated or truncated:
                break
        onset = info.get("fault_time")
        # the settled operation only: the start-up move is not what the supervisor monitors
        y = np.asarray(rows, dtype=np.float64)[ARM_AFTER:]
        onset = None if onset is None else onset - ARM_AFTER
        out.append(
            Episode(
                y,
                CLOSED_LOOP_CHANNELS,
                PlantConfig().sample_time_s,
                fault_onset=onset if onset is not None and onset < len(y) else None,
                scenario=scenario,
                seed=seed,
            )
        )
        env.close()
    return out


def supervisor(
    name: str, n_steps: int = 3999, params: dict[str, Any] | None = None
) -> DiagnosisSupervisor:
    """A :class:`DiagnosisSupervisor` around registered diagnoser ``name``, trained on episodes
    of :data:`TRAIN_SEEDS` run at the supervisor's healthy set points (healthy ones, and for an
    isolator or a detector that learns from faults each fault at its default size too, on the
    same seeds: each faulty episode's healthy twin is there). Trained on the operating program instead, a
    detector alarms as soon as the supervisor moves the set points to their optimum: the unit
    has left the region it learned (every episode, pca and lrgf-glr-closed alike, measured)."""
    from diagnosers import diagnoser_class, make

    fixed = fixed_setpoints()
    train = operated_episodes(fixed, "nominal", TRAIN_SEEDS, n_steps)
    cls = diagnoser_class(name)
    if cls.isolates or cls.learns_from_faults:
        for fault in fault_names():
            train += operated_episodes(fixed, fault, TRAIN_SEEDS, n_steps)
    label = name + "".join(f" {k}={v}" for k, v in (params or {}).items())
    return DiagnosisSupervisor(
        f"supervisor on {label}",
        make(name, **(params or {})).fit(train),
        fixed.target(0, {}),
        fault_setpoints(),
    )


def _table(summaries: Sequence[PolicySummary]) -> str:
    def ci(i: Interval) -> str:
        return f"{i.estimate:,.0f} [{i.low:,.0f}, {i.high:,.0f}]"

    lines = [
        "| policy | return per episode [USD] | trips per 100 episodes | time in constraint "
        "regions | loss against the oracle [USD] |",
        "|---|---|---|---|---|",
    ]
    for s in summaries:
        lines.append(
            f"| {s.policy} | {ci(s.return_usd)} | {s.trips_per_100:.1f} | "
            f"{100 * s.constraint_share:.2f} % | {ci(s.loss_vs_oracle_usd)} |"
        )
    return "\n".join(lines) + "\n"


def _json(text: str) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise argparse.ArgumentTypeError(f"{text!r} is not JSON ({e})") from None


def main(argv: Sequence[str] | None = None, extra_policies: Sequence[Policy] = ()) -> int:
    """The command; ``extra_policies`` run beside the baselines (before the oracle)."""
    parser = command_parser(
        "evaluation.control",
        __doc__ or "",
        (
            ("--seeds 20", "the baselines and a pca-driven supervisor, 100 episodes each"),
            ("--seeds 2 --diagnosers ''", "a quick look at the baselines alone"),
            ("--diagnosers pca,lrgf-glr-closed", "what two detectors are worth as supervisors"),
            (
                '--diagnosers lrgf-iso --diagnoser-params \'{"lrgf-iso": {"detector_name": '
                '"lrgf-glr-closed"}}\'',
                "an isolator on the closed-loop detector: it names the fault",
            ),
        ),
    )
    parser.add_argument("--seeds", type=int, default=20, help="test seeds per scenario (20)")
    parser.add_argument("--steps", type=int, default=3999, help="steps per episode (3999)")
    parser.add_argument("--out", type=out_path, default=Path("results/control"))
    parser.add_argument(
        "--diagnosers",
        default="pca",
        help="comma-separated registered diagnosers, each driving a supervisor (pca); '' none",
    )
    parser.add_argument(
        "--diagnoser-params",
        type=_json,
        default={},
        metavar="JSON",
        help='hyperparameters per diagnoser, e.g. \'{"lrgf-iso": {"detector_name": '
        "\"lrgf-glr-closed\"}}' (as a manifest's diagnoser_params)",
    )
    return run_command(parser, lambda args: _study(args, extra_policies), argv)


def _study(args: argparse.Namespace, extra_policies: Sequence[Policy] = ()) -> int:
    """The work of :func:`main`: its failures are refused by :func:`run_command`."""
    from diagnosers import available

    if args.seeds < 1 or not 1 <= args.steps <= 3999:
        raise ValueError(
            f"--seeds {args.seeds} / --steps {args.steps}: allowed --seeds >= 1, --steps 1..3999"
        )
    check_out_path("--out", args.out)
    names = [n for n in args.diagnosers.split(",") if n]
    unknown = [n for n in names if n not in available()]
    if unknown:
        raise ValueError(f"--diagnosers: unknown {unknown}; allowed: {available()}")
    t0 = time.perf_counter()
    policies: list[Policy] = [ProgramPolicy(), fixed_setpoints()]
    params = args.diagnoser_params
    if not isinstance(params, dict) or not all(isinstance(v, dict) for v in params.values()):
        raise ValueError(
            f"--diagnoser-params {params!r}: allowed: a JSON object mapping diagnoser names to "
            "objects of hyperparameters"
        )
    stray = sorted(set(params) - set(names))
    if stray:
        raise ValueError(f"--diagnoser-params names {stray}, which --diagnosers does not")
    # supervisors on the same relations (lrgf-iso around lrgf-glr-closed and lrgf-glr-closed)
    # train them once
    with shared_relations(args.out / "relations"):
        policies += [supervisor(n, params=params.get(n)) for n in names]
    policies += list(extra_policies)
    policies.append(oracle())
    scenarios = scenario_names()
    scores = run_study(policies, range(args.seeds), args.steps, scenarios)
    summaries = summarise(scores, reference=policies[-1].name)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = [asdict(s) for s in scores]
    header = ",".join(rows[0])
    body = "\n".join(",".join(str(v) for v in r.values()) for r in rows)
    atomic_write(args.out / "control.csv", header + "\n" + body + "\n")
    atomic_write_json(
        args.out / "control.json",
        {"summaries": [asdict(s) for s in summaries], "episodes": rows},
    )
    figures = []
    for scenario in scenarios[1:]:  # one episode per fault, every policy: what each did
        traces: dict[str, dict[str, list[Any]]] = {}
        for p in policies:
            traces[p.name] = {}
            run_episode(p, scenario, 0, args.steps, trace=traces[p.name])
        figures.append(
            episode_figure(
                traces,
                PlantConfig().sample_time_s,  # the registered env's
                args.out / f"episode_{scenario}.png",
                title=f"FCC-control-v0, {scenario} at the paper's size and onset, test seed 0",
            )
        )
    print(_table(summaries), end="")
    print(
        f"\n{len(scores)} episodes ({args.seeds} test seeds x {len(scenarios)} scenarios x "
        f"{len(policies)} policies) in {time.perf_counter() - t0:.0f} s; wrote {args.out} "
        f"(control.csv, control.json, {len(figures)} figures)",
    )
    return 0
