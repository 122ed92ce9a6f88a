"""The control study as a library: policies scored on ``FCC-control-v0`` episodes, with intervals.

Each policy (:mod:`evaluation.control.policies`) runs the same episodes: the healthy plant and
each fault at the paper's size and onset, on the given seeds (the command's are the test seeds
0..; nothing here is tuned, the set points come from the steady-state search). Per policy
(:class:`PolicySummary`): the mean return per episode (USD) with its 95 % bootstrap interval,
trips per 100 episodes, the share of samples inside a constraint region (a term of
:data:`fcc_env.control_task.CONSTRAINT_TERMS` below zero) and the loss against a reference
policy, the oracle in the command (its return minus the policy's, paired by episode, with its
interval).

Pure computation: every function returns data (:class:`EpisodeScore`, :class:`StudyResults`,
the traces a figure draws); the tables and files are :mod:`evaluation.control.returns_report`'s,
the command line :mod:`evaluation.control.returns_command`'s.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from diagnosers.episode.record import Episode
from evaluation.control.policies import (
    ARM_AFTER,
    DiagnosisSupervisor,
    Policy,
    fault_setpoints,
    fixed_setpoints,
)
from evaluation.metrics.intervals import Interval, bootstrap_ci
from fcc_common.progress import progress_bar
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.control_draws import FaultClass, fault_class
from fcc_env.control_task import CONSTRAINT_TERMS, CONTROL_ENV_ID
from fcc_env.faults import RANDOM_SCENARIO
from fcc_env.plant import PlantConfig
from fcc_env.scenarios import fault_names, scenario_names

__all__ = [
    "TRAIN_SEEDS",
    "EpisodeScore",
    "PolicySummary",
    "StudyResults",
    "class_summaries",
    "fault_traces",
    "operated_episodes",
    "run_episode",
    "run_study",
    "study",
    "summarise",
    "supervisor",
]

#: Training episodes of a supervisor's diagnoser: seeds 1000.. (never a test seed).
TRAIN_SEEDS = range(1000, 1009)


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


@dataclass(frozen=True)
class StudyResults:
    """A study's outcome: every episode's score, in the order run (policy, scenario, seed), and
    each policy's summary against ``reference`` (a policy's name)."""

    scores: tuple[EpisodeScore, ...]
    summaries: tuple[PolicySummary, ...]
    reference: str
    seeds: tuple[int, ...]
    scenarios: tuple[str, ...]
    n_steps: int


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
    if scenario == RANDOM_SCENARIO:  # a drawn fault: the score names what was drawn
        scenario = str(info["scenario"])
    if trace is not None:
        trace["onset"] = [info.get("fault_time")]
    total, inside, tripped, k = 0.0, 0, False, 0
    for k in range(1, n_steps + 1):  # noqa: B007 (k is the episode's length after the loop)
        obs, reward, terminated, truncated, info = env.step(policy.act(obs, info))
        total += float(reward)
        inside += any(info["reward_terms"][t] < 0.0 for t in CONSTRAINT_TERMS)
        if trace is not None:
            for key, value in (("reward", reward), ("setpoints", info["setpoints"])):
                trace.setdefault(key, []).append(np.copy(value))
            trace.setdefault("state", []).append(info["state"].copy())
        if terminated or truncated:
            tripped = bool(terminated)
            break
    env.close()
    return EpisodeScore(policy.name, scenario, seed, total, tripped, inside / k, k)


def class_summaries(
    scores: Sequence[EpisodeScore], reference: str
) -> dict[str, list[PolicySummary]]:
    """:func:`summarise` per fault class (:class:`fcc_env.control_draws.FaultClass`, of each
    episode's scenario), the classes in their order, only those with episodes."""
    out = {}
    for cls in FaultClass:
        mine = [s for s in scores if fault_class(s.scenario) is cls]
        if mine:
            out[cls.value] = summarise(mine, reference=reference)
    return out


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
    policies: Sequence[Policy],
    seeds: Sequence[int],
    n_steps: int,
    scenarios: Sequence[str],
    *,
    progress: bool | None = False,
    **env_kwargs: Any,
) -> list[EpisodeScore]:
    """Every policy on every scenario and seed, in that order. ``progress``: a bar over the
    episodes on standard error (``None``: when it is a terminal; :mod:`fcc_common.progress`).
    ``env_kwargs`` go to ``gym.make`` (``catalogue="all"`` with the scenario ``"random"``: the
    whole catalogue's draws, each score named by its drawn scenario)."""
    runs = [(p, sc, seed) for p in policies for sc in scenarios for seed in seeds]
    scores = []
    with progress_bar(
        total=len(runs), desc="control study", unit="episode", progress=progress
    ) as bar:
        for p, sc, seed in runs:
            bar.set_postfix_str(f"{p.name}, {sc}", refresh=False)
            scores.append(run_episode(p, sc, seed, n_steps, **env_kwargs))
            bar.update()
    return scores


def study(
    policies: Sequence[Policy],
    seeds: Sequence[int],
    n_steps: int,
    scenarios: Sequence[str] | None = None,
    *,
    progress: bool | None = False,
    **env_kwargs: Any,
) -> StudyResults:
    """:func:`run_study` (``progress`` and ``env_kwargs`` as there) and :func:`summarise`,
    against the last policy (the oracle, in the command: the reference sits last in the table);
    ``scenarios`` default to every registered one."""
    scenarios = scenario_names() if scenarios is None else scenarios  # the registry, now
    scores = run_study(policies, seeds, n_steps, scenarios, progress=progress, **env_kwargs)
    reference = policies[-1].name
    return StudyResults(
        tuple(scores),
        tuple(summarise(scores, reference=reference)),
        reference,
        tuple(seeds),
        tuple(scenarios),
        n_steps,
    )


def fault_traces(
    policies: Sequence[Policy], n_steps: int, seed: int = 0, *, progress: bool | None = False
) -> dict[str, dict[str, dict[str, list[Any]]]]:
    """Per fault (at the paper's size and onset), per policy, the ``trace`` of
    :func:`run_episode` on seed ``seed``: what each policy did, for a figure. ``progress`` as
    :func:`run_study`'s."""
    out: dict[str, dict[str, dict[str, list[Any]]]] = {}
    faults = fault_names()
    total = len(faults) * len(policies)
    with progress_bar(total=total, desc="fault traces", unit="episode", progress=progress) as bar:
        for scenario in faults:
            out[scenario] = {}
            for p in policies:
                out[scenario][p.name] = {}
                run_episode(p, scenario, seed, n_steps, trace=out[scenario][p.name])
                bar.update()
    return out


def operated_episodes(
    policy: Policy,
    scenario: str,
    seeds: Sequence[int],
    n_steps: int,
    *,
    progress: bool | None = False,
) -> list[Episode]:
    """``FCC-control-v0`` episodes run by ``policy``, as the diagnoser of a supervisor sees them
    (its training data must come from the operation it will monitor). ``progress`` as
    :func:`run_study`'s."""
    out = []
    desc = f"training episodes ({scenario})"
    for seed in progress_bar(seeds, desc=desc, unit="episode", progress=progress):
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
    name: str,
    n_steps: int = 3999,
    params: dict[str, Any] | None = None,
    *,
    progress: bool | None = False,
) -> DiagnosisSupervisor:
    """A :class:`DiagnosisSupervisor` around registered diagnoser ``name``, trained on episodes
    of :data:`TRAIN_SEEDS` run at the supervisor's healthy set points (healthy ones, and for an
    isolator or a detector that learns from faults each fault at its default size too, on the
    same seeds: each faulty episode's healthy twin is there). Trained on the operating program instead, a
    detector alarms as soon as the supervisor moves the set points to their optimum: the unit
    has left the region it learned (every episode, pca and lrgf-glr-closed alike, measured).
    ``progress``: a bar over the training episodes (as :func:`run_study`'s)."""
    from diagnosers import diagnoser_class, make

    fixed = fixed_setpoints()
    train = operated_episodes(fixed, "nominal", TRAIN_SEEDS, n_steps, progress=progress)
    cls = diagnoser_class(name)
    if cls.isolates or cls.learns_from_faults:
        for fault in fault_names():
            train += operated_episodes(fixed, fault, TRAIN_SEEDS, n_steps, progress=progress)
    label = name + "".join(f" {k}={v}" for k, v in (params or {}).items())
    return DiagnosisSupervisor(
        f"supervisor on {label}",
        make(name, **(params or {})).fit(train),
        fixed.target(0, {}),
        fault_setpoints(),
    )
