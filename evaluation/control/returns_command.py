"""``python -m evaluation.control``: the control task's baselines on test seeds, with intervals.

Each policy (:mod:`evaluation.control.policies`) runs ``FCC-control-v0`` on the same episodes:
the healthy plant and each fault at the paper's size and onset, ``--seeds`` test seeds each
(seeds 0.., the benchmark's test range; nothing here is tuned, the set points come from the
steady-state search). Per policy: the mean return per episode (USD) with its 95 % bootstrap
interval, trips per 100 episodes, the share of samples inside a constraint region (any
constraint term of the reward below zero: fcc_env.control_task.CONSTRAINT_TERMS), and the loss
against the oracle (its return minus the policy's, paired by episode, with its interval).
Written to ``--out`` as ``control.csv`` and ``control.json``; the table is printed. Progress
bars (episodes run, the supervisors' training episodes) go to standard error when it is a
terminal, or with ``--progress``; ``--no-progress`` turns them off.

``--catalogue all`` runs draws of the whole fault catalogue instead (``FCC-control-v0``'s
``catalogue="all"``: healthy, process, sensor and actuator faults, a class a quarter of the
draws, :mod:`fcc_env.control_draws`): ``4 × --seeds`` episodes, one per test seed, and a table
per fault class besides the overall one.

``--policies`` (default ``program,fixed``) names the registered policies that run first
(:mod:`evaluation.control.policy_registry`; one of your own joins with ``--import MODULE``); the
oracle runs last, as the reference. ``--diagnosers`` (default ``pca``) adds a diagnosis-driven
supervisor per registered diagnoser
(:class:`~evaluation.control.policies.DiagnosisSupervisor`), trained on episodes of the training
seeds (1000..) run at its healthy set points (healthy, and for an isolator each fault at the
paper's size too):
what its alarms and diagnoses are worth in money and trips. A reinforcement-learning agent joins
the table through ``python -m evaluation.control.rl evaluate`` (:mod:`evaluation.control.rl`).

The study is :mod:`evaluation.control.returns` (computation) and
:mod:`evaluation.control.returns_report` (table, files, figures); this module parses and prints.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from evaluation.control.policy_registry import available_policies, make_policy, policy_spec
from fcc_common.invocation import (
    check_out_path,
    command_parser,
    csv_list,
    import_from_cwd,
    out_path,
    run_command,
    user_modules,
)
from fcc_common.progress import add_progress_flag

if TYPE_CHECKING:
    from evaluation.control.policies import Policy

__all__ = ["DEFAULT_POLICIES", "REFERENCE_POLICY", "build_parser", "main"]

#: The policies ``--policies`` runs by default, before the supervisors.
DEFAULT_POLICIES = ("program", "fixed")
#: The policy every study runs last, the reference of the loss column.
REFERENCE_POLICY = "oracle"


def _json(text: str) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise argparse.ArgumentTypeError(f"{text!r} is not JSON ({e})") from None


def build_parser() -> argparse.ArgumentParser:
    """The command's parser (also ``python -m evaluation.leaderboard --task control``'s)."""
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
            (
                "--import my_policies --policies program,fixed,my-policy --diagnosers ''",
                'a policy of your own: my_policies.py registers it with @register_policy("my-'
                'policy") (evaluation.control.register_policy; run from its directory)',
            ),
        ),
    )
    parser.add_argument("--seeds", type=int, default=20, help="test seeds per scenario (20)")
    parser.add_argument("--steps", type=int, default=3999, help="steps per episode (3999)")
    parser.add_argument(
        "--catalogue",
        choices=("paper", "all"),
        default="paper",
        help="paper: each of f1-f4 at its paper size (the default); all: draws of the whole "
        "catalogue, 4 x --seeds episodes, tabled per fault class",
    )
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
    parser.add_argument(
        "--policies",
        default=",".join(DEFAULT_POLICIES),
        metavar="A,B",
        help=f"comma-separated registered policies, run before the supervisors "
        f"({','.join(DEFAULT_POLICIES)}); '' none. The {REFERENCE_POLICY} always runs, last",
    )
    parser.add_argument(
        "--import",
        dest="imports",
        type=csv_list,
        action="append",
        default=[],
        metavar="MODULE[,MODULE]",
        help="import these modules first (repeatable): modules that register policies "
        "(@evaluation.control.register_policy, named in --policies) or diagnosers "
        "(@diagnosers.register, named in --diagnosers). Imported (not run), from the current "
        "directory or the installed packages",
    )
    add_progress_flag(parser)
    return parser


def main(argv: Sequence[str] | None = None, extra_policies: Sequence[Policy] = ()) -> int:
    """The command; ``extra_policies`` run beside the baselines (before the oracle)."""
    return run_command(build_parser(), lambda args: _study(args, extra_policies), argv)


def _policy_names(text: str) -> list[str]:
    """``--policies``' names, checked: registered, made without arguments, not the oracle."""
    names = [n for n in text.split(",") if n]
    unknown = [n for n in names if n not in available_policies()]
    if unknown:
        raise ValueError(f"--policies: unknown {unknown}; allowed: {available_policies()}")
    if REFERENCE_POLICY in names:
        raise ValueError(
            f"--policies names {REFERENCE_POLICY!r}, which every study runs, last, as the "
            "reference of the loss column; leave it out"
        )
    needy = {n: policy_spec(n).needs for n in names if policy_spec(n).needs}
    if needy:
        raise ValueError(
            f"--policies: {sorted(needy)} need arguments ({'; '.join(needy.values())}); "
            "name policies that need none"
        )
    if len(set(names)) != len(names):
        raise ValueError(f"--policies repeats a name: {names}")
    return names


def _study(args: argparse.Namespace, extra_policies: Sequence[Policy] = ()) -> int:
    """The work of :func:`main`: its failures are refused by :func:`run_command`."""
    # imported here, after parsing: --help and argparse's refusals answer at once
    from diagnosers import available
    from diagnosers.bank.relation_cache import shared_relations
    from diagnosers.registry import import_modules
    from evaluation.control import returns, returns_report
    from fcc_env.scenarios import scenario_names

    scenarios = scenario_names()

    most = returns.TRAIN_SEEDS.start  # test seeds 0.. stay below the training seeds
    if not 1 <= args.seeds <= most or not 1 <= args.steps <= 3999:
        raise ValueError(
            f"--seeds {args.seeds} / --steps {args.steps}: allowed --seeds 1..{most} (test seeds "
            f"0..{most - 1}, below the training seeds {most}..), --steps 1..3999"
        )
    check_out_path("--out", args.out)
    try:  # before any name is resolved
        import_from_cwd(user_modules(args.imports), import_modules)
    except ValueError as e:
        raise ValueError(f"--import: {e}") from None
    names = [n for n in args.diagnosers.split(",") if n]
    unknown = [n for n in names if n not in available()]
    if unknown:
        raise ValueError(f"--diagnosers: unknown {unknown}; allowed: {available()}")
    chosen = _policy_names(args.policies)
    t0 = time.perf_counter()
    params = args.diagnoser_params
    if not isinstance(params, dict) or not all(isinstance(v, dict) for v in params.values()):
        raise ValueError(
            f"--diagnoser-params {params!r}: allowed: a JSON object mapping diagnoser names to "
            "objects of hyperparameters"
        )
    stray = sorted(set(params) - set(names))
    if stray:
        raise ValueError(f"--diagnoser-params names {stray}, which --diagnosers does not")
    policies: list[Policy] = [make_policy(n) for n in chosen]
    # supervisors on the same relations (lrgf-iso around lrgf-glr-closed and lrgf-glr-closed)
    # train them once
    with shared_relations(args.out / "relations"):
        policies += [
            make_policy("supervisor", name=n, params=params.get(n), progress=args.progress)
            for n in names
        ]
    policies += list(extra_policies)
    policies.append(make_policy(REFERENCE_POLICY))
    shown = [p.name for p in policies]
    if len(set(shown)) != len(shown):
        raise ValueError(
            f"two policies share a name in the table: {shown}; give each policy its own name"
        )
    env_kwargs = {}
    seeds = range(args.seeds)
    if args.catalogue == "all":
        scenarios, env_kwargs, seeds = ["random"], {"catalogue": "all"}, range(4 * args.seeds)
        if seeds.stop > most:
            raise ValueError(f"--seeds {args.seeds} with --catalogue all: allowed 1..{most // 4}")
    results = returns.study(
        policies, seeds, args.steps, scenarios, progress=args.progress, **env_kwargs
    )
    traces = returns.fault_traces(policies, args.steps, seed=0, progress=args.progress)
    figures = returns_report.write_study(results, traces, args.out, trace_seed=0)
    print(returns_report.summary_table(results.summaries), end="")
    if args.catalogue == "all":
        for name, rows in returns.class_summaries(results.scores, results.reference).items():
            print(f"\n{name} faults:\n" + returns_report.summary_table(rows), end="")
    print(
        f"\n{len(results.scores)} episodes ({len(seeds)} test seeds x {len(scenarios)} "
        f"scenarios x {len(policies)} policies) in {time.perf_counter() - t0:.0f} s; wrote "
        f"{args.out} (control.csv, control.json, {len(figures)} figures)",
    )
    return 0
