"""Leaderboard CLI: ``python -m evaluation.leaderboard [--quick] [...]``.

Runs a sweep (:func:`evaluation.sweep.run_sweep`), then writes into ``--out``
(default ``results/leaderboard``; ``results/external`` with ``--external``, so that recorded data
never overwrite the simulated tables):

* ``leaderboard.md`` - the Markdown table printed to stdout (its legend,
  :func:`~evaluation.reports.tables.table_legend`, is in the file's header and printed to
  stdout after the table, a blank line between; progress and timings go to stderr): one row
  per diagnoser plus the paper's Table 2 as a reference row; columns ``r_fd`` on healthy episodes, then ``r_td`` and
  ``t_dt`` for each fault, each mean ± standard deviation over test seeds, with the miss count.
* ``leaderboard.csv`` - one row per diagnoser × scenario: ``diagnoser, scenario, n_seeds, r_fd,
  r_fd_std, r_td, r_td_std, t_dt, t_dt_std, t_dt_s, t_dt_s_std, misses, n_detected,
  n_terminated, data, package_version``. For a fault scenario ``r_fd`` is the false detection
  rate *before the onset*; for a healthy one it covers the whole episode.
* ``results.csv`` / ``results.json`` - the raw per-seed cells (JSON adds the sweep description).
* ``figures/<scenario>/<diagnoser>.png`` - Fig. 3/4-style plots on the first test seed.
* ``store/<hash>/`` - the resumable result store (re-running the same command resumes; a
  sweep with other data options gets another hash, so ``--quick`` and the full sweep coexist).

Units: ``t_dt`` in samples (``Ts`` = 10 s for FCC-v0; the CSV also has ``t_dt_s`` in seconds), as
in the paper's Table 2. Mean ``t_dt`` is over detected faults only; ``misses`` counts the test
episodes whose fault was never detected. Standard deviations use ``ddof=1`` (``–`` with one seed).

Diagnosers of your own: ``--import MODULE[,MODULE]`` imports modules that register them
(``@diagnosers.register``) before any name is resolved, here and in every worker
(:attr:`evaluation.sweep.SweepConfig.imports`); installed packages can use the
``fcc_fault_diagnosis.diagnosers`` entry-point group instead (:mod:`diagnosers.registry`).

``--task control`` is the control task's leaderboard, ``python -m evaluation.control``
(:mod:`evaluation.control.returns_command`): ``--task`` is read first by a parser of its own
(``parse_known_args``), and the other words go to the command the task names.

Table formatting (:mod:`evaluation.reports.tables`) is separate from computation
(:func:`evaluation.leaderboard.paper.run`), from writing the files (:mod:`evaluation.reports.outputs`)
and from the command line (:func:`main`), the only place that prints.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

from evaluation.leaderboard.arguments import (
    BASELINES,
    DEFAULT_OUT,
    DEFAULT_SEEDS,
    DEFAULT_TRAIN_EPISODES,
    EXTERNAL_OUT,
    QUICK_SEEDS,
    QUICK_TRAIN_EPISODES,
    VALIDATION_FAULT_SCALE,
    VALIDATION_OUT,
    VALIDATION_SEED_BASE,
    VALIDATION_SEEDS,
    build_parser,
    check_backend,
    check_counts,
    check_out_dir,
    exit_on_failure,
    import_user_modules,
    user_imports,
)
from fcc_common.invocation import run_command

if TYPE_CHECKING:
    from evaluation.leaderboard.paper import LeaderboardOptions

__all__ = ["main", "resolve_options"]


def resolve_options(
    args: argparse.Namespace, parser: argparse.ArgumentParser
) -> LeaderboardOptions:
    """Fill defaults (``--quick`` or full) and check names against the allowed sets."""
    # imported here, after parsing, so that --help and argparse's refusals answer at once
    import fcc_env
    from diagnosers.range_guard import RangeGuard
    from diagnosers.registry import available, diagnoser_class
    from diagnosers.stages.operating_range import SETPOINT_CHANNELS
    from evaluation.leaderboard.paper import LeaderboardOptions
    from evaluation.sweep.dataset_loaders import load_external
    from evaluation.tracks.board import applicable
    from fcc_env.scenarios import FaultSpec

    if args.test_seed_start is not None:
        parser.error(
            f"--test-seed-start {args.test_seed_start} applies to --track; the paper "
            "leaderboard's test seeds are 0..--seeds−1 (--validation: 5000..)"
        )

    avail = available()
    if args.diagnosers is not None:
        diags = args.diagnosers
    elif args.quick:
        diags = tuple(d for d in BASELINES if d in avail)
    else:
        diags = tuple(avail)
        if args.external is not None:
            # recorded data have no labelled training faults, and another unit is not the
            # published FCC model a grey-box diagnoser knows: the black box tier only
            diags = tuple(
                d
                for d in diags
                if not diagnoser_class(d).isolates and diagnoser_class(d).tier == "black box"
            )
        else:  # FCC-v0's channels: a closed-loop detector (it reads u_F) has nothing to read
            diags = tuple(applicable(diags, fcc_env.MEASUREMENT_NAMES, "")[0])
    unknown = [d for d in diags if d not in avail]
    if unknown:
        parser.error(f"unknown diagnoser(s) {unknown}. Available: {avail}")
    if args.external is not None:
        try:
            data, ext_params = load_external(args.external)
        except ValueError as e:
            parser.error(f"--external {args.external}: {e}")
        allowed = [tf.key for tf in data.test_files]
        # a detector whose relations name channels the data lack is dropped before training
        # (named by the user: refused), with the data set's own relations where it gives some
        if args.diagnosers is None and not set(SETPOINT_CHANNELS) & set(data.channels):
            # a novelty variant is its base plus a flag on the set points: without them it
            # would repeat its base's row (and its base is in the list), so it is left out
            diags = tuple(d for d in diags if not issubclass(diagnoser_class(d), RangeGuard))
        keep, skipped = applicable(diags, data.channels, f"on {args.external}", ext_params)
        if skipped and args.diagnosers is not None:
            parser.error("; ".join(skipped) + " (declare its relations in the manifest)")
        for line in skipped:
            print(line, file=sys.stderr)
        diags = tuple(keep)
    else:
        allowed = list(fcc_env.scenario_names())
    scenarios = args.scenarios if args.scenarios is not None else tuple(allowed)
    bad = [s for s in scenarios if s not in allowed]
    if bad:
        parser.error(f"unknown scenario(s) {bad}. Allowed: {allowed}")
    if len(set(scenarios)) != len(scenarios):
        parser.error(f"--scenarios repeats a name: {list(scenarios)}")
    if args.workers is not None and args.workers < 0:
        parser.error(f"--workers must be >= 0, got {args.workers}")
    if args.ray_address is not None and args.backend != "ray":
        parser.error("--ray-address needs --backend ray")
    if args.ramp_samples is not None and args.fault_profile != "incipient":
        parser.error("--ramp-samples needs --fault-profile incipient")
    if args.validation and (args.quick or args.external is not None):
        parser.error("--validation cannot be combined with --quick or --external")
    # recorded data get a folder of their own: never the --quick run's tables
    out = args.out or (
        VALIDATION_OUT
        if args.validation
        else EXTERNAL_OUT
        if args.external is not None
        else DEFAULT_OUT
    )
    try:
        check_backend(args.backend)
        check_out_dir(out)
    except ValueError as e:
        parser.error(str(e))
    if args.validation:
        seeds = args.seeds or VALIDATION_SEEDS
    else:
        seeds = args.seeds or (QUICK_SEEDS if args.quick else DEFAULT_SEEDS)
    train = args.train_episodes or (QUICK_TRAIN_EPISODES if args.quick else DEFAULT_TRAIN_EPISODES)
    if args.external is None:  # recorded data: the files set the counts
        try:  # before any range of seeds is built
            check_counts(
                seeds=seeds,
                seed_base=VALIDATION_SEED_BASE if args.validation else 0,
                train_episodes=train,
                n_samples=args.n_samples,
                n_cells_per_seed=len(scenarios) * max(1, len(diags)),
            )
        except ValueError as e:
            parser.error(str(e))
    try:
        fault = FaultSpec(
            onset=args.fault_time,
            magnitude_scale=VALIDATION_FAULT_SCALE if args.validation else 1.0,
            profile=args.fault_profile,
            ramp_samples=args.ramp_samples,
        )
    except ValueError as e:
        parser.error(str(e))
    return LeaderboardOptions(
        diagnosers=diags,
        scenarios=scenarios,
        seeds=seeds,
        train_episodes=train,
        out=out,
        backend=args.backend,
        workers=args.workers,
        ray_address=args.ray_address,
        n_samples=args.n_samples,
        fault=fault,
        external=args.external,
        figures=not args.no_figures,
        progress=not args.no_progress,
        seed_base=VALIDATION_SEED_BASE if args.validation else 0,
        imports=user_imports(args),
    )


def main(argv: Sequence[str] | None = None) -> int:
    words = list(sys.argv[1:] if argv is None else argv)
    task, rest = _split_task(words)
    if task == "control":
        # the control task's leaderboard has options of its own: its command parses them
        from evaluation.control.returns_command import main as control_main

        return control_main(rest)
    parser = build_parser()
    resume = "finished cells are stored: re-run the same command to resume"
    return run_command(parser, lambda args: _leaderboard(args, parser), words, on_interrupt=resume)


def _split_task(words: Sequence[str]) -> tuple[str | None, list[str]]:
    """``--task`` (``--task X`` or ``--task=X``, spelled out) and the other words, by argparse.

    The task picks the command that parses the rest, so it is read first, alone
    (``parse_known_args``); anything this cannot read (no value) is left to the leaderboard's
    parser to refuse, which also refuses a task that is not one of its choices.
    """
    first = argparse.ArgumentParser(add_help=False, allow_abbrev=False, exit_on_error=False)
    first.add_argument("--task")
    try:
        known, rest = first.parse_known_args(words)
    except argparse.ArgumentError:
        return None, list(words)
    return known.task, rest


def _leaderboard(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """The work of :func:`main`: a bad value or path found late is refused by
    :func:`~fcc_common.invocation.run_command`, a failed run by :func:`exit_on_failure`."""
    if args.task == "control":  # an abbreviation of --task, which main does not read
        parser.error("--task control: spell --task out (an abbreviation is not read)")
    import_user_modules(args, parser)  # before any name is resolved
    if args.track is not None:
        from evaluation.leaderboard.track_runs import main_tracks  # after parsing: see above

        return main_tracks(args, parser)
    from evaluation.leaderboard import paper
    from evaluation.reports.outputs import marked_results, write_outputs
    from evaluation.reports.tables import markdown_table, reference_row, sample_time, table_legend

    opts = resolve_options(args, parser)
    t0 = time.perf_counter()
    try:
        results = paper.run(opts)
    except ValueError as e:  # bad configuration: say what and exit like argparse does
        parser.error(str(e))
    except (RuntimeError, KeyboardInterrupt) as e:  # finished cells are kept
        exit_on_failure(parser, e)
    written = write_outputs(results, opts.out, figures=opts.figures)
    results = marked_results(results)  # as in the file: the † of an assumed onset, its legend
    reference = reference_row(results.config)
    # stdout is the table and its legend (`> table.md` keeps both); progress goes to stderr
    print(markdown_table(results.summary(), reference=reference))
    assumed = any(r.onset_assumed for r in results.records)  # as the file's header says it
    print(table_legend(sample_time(results), onset_assumed=assumed), flush=True)
    print(
        f"{results.n_computed} cells computed, {results.n_reused} reused, "
        f"{results.n_trained} diagnosers trained in {time.perf_counter() - t0:.1f} s; "
        f"wrote {len(written)} files to {opts.out}",
        file=sys.stderr,
    )
    return 0
