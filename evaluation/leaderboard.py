"""Leaderboard CLI: ``python -m evaluation.leaderboard [--quick] [...]``.

Runs a sweep (:func:`evaluation.harness.run_sweep`), then writes into ``--out``
(default ``results/leaderboard``):

* ``leaderboard.md`` - the Markdown table printed to stdout (its legend, :func:`table_legend`, is
  in the file's header and printed to stderr): one row per diagnoser plus the
  paper's Table 2 as a reference row; columns ``r_fd`` on healthy episodes, then ``r_td`` and
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

Table formatting (:func:`markdown_table`, :func:`summary_rows`) is separate from computation
(:func:`run`), from writing the files (:mod:`evaluation.outputs`) and from the CLI (:func:`main`),
the only place that prints.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

from diagnosers.registry import import_modules
from evaluation.harness import (
    BACKENDS,
    BASELINES,
    TRAIN_SEED_BASE,
    DiagnoserSpec,
    SimulatedData,
    SweepConfig,
    SweepResults,
    default_specs,
    run_sweep,
)
from evaluation.outputs import figure_cells, write_outputs
from evaluation.store import canonical_hash
from evaluation.tables import (
    PAPER_TABLE2,
    markdown_table,
    reference_row,
    sample_time,
    summary_rows,
    table_legend,
)

if TYPE_CHECKING:
    from evaluation.tracks import Track

__all__ = [
    "PAPER_TABLE2",
    "LeaderboardOptions",
    "build_parser",
    "main",
    "markdown_table",
    "run",
    "summary_rows",
    "table_legend",
    "track_options",
    "write_outputs",
]

QUICK_SEEDS = 3
QUICK_TRAIN_EPISODES = 3
DEFAULT_SEEDS = 10
DEFAULT_TRAIN_EPISODES = 9  # lrgf-mem: 6 to train the models, 3 held out to calibrate
DEFAULT_OUT = Path("results/leaderboard")
#: The validation protocol on which ``lrgf-mem``'s hyperparameters were chosen: seeds the test
#: sweep (0..N-1) and the training (1000..) never use, faults at 0.7x the paper's magnitudes.
VALIDATION_SEED_BASE = 5000
VALIDATION_SEEDS = 40
VALIDATION_FAULT_SCALE = 0.7
VALIDATION_OUT = Path("results/validation")


# ---- options -----------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class LeaderboardOptions:
    """Resolved CLI options (what :func:`run` needs)."""

    diagnosers: tuple[str, ...]
    scenarios: tuple[str, ...]
    seeds: int
    train_episodes: int
    out: Path
    backend: str = "local"
    workers: int | None = None
    ray_address: str | None = None
    n_samples: int = 4000
    fault_time: int | None = None
    external: Path | None = None
    figures: bool = True
    progress: bool = True
    seed_base: int = 0
    fault_magnitude_scale: float = 1.0
    fault_profile: str = "abrupt"
    ramp_samples: int | None = None
    imports: tuple[str, ...] = ()


def build_config(opts: LeaderboardOptions) -> SweepConfig:
    """The sweep the options describe (validated by :func:`run_sweep`)."""
    if opts.external is not None:
        from evaluation.external import load_external

        data, ext_params = load_external(opts.external)
        keep = set(opts.scenarios)
        data = dataclasses.replace(
            data, test_files=tuple(tf for tf in data.test_files if tf.key in keep)
        )
        specs = []
        for name in opts.diagnosers:
            # defaults that name FCC-v0 channels get the Santander analogue
            params = ext_params.get(name, {})
            specs.append(DiagnoserSpec(name, dict(params)))
        return SweepConfig(diagnosers=tuple(specs), data=data, imports=opts.imports)
    data = SimulatedData(
        scenarios=opts.scenarios,
        test_seeds=tuple(range(opts.seed_base, opts.seed_base + opts.seeds)),
        train_seeds=tuple(range(TRAIN_SEED_BASE, TRAIN_SEED_BASE + opts.train_episodes)),
        n_samples=opts.n_samples,
        fault_time=opts.fault_time,
        fault_magnitude_scale=opts.fault_magnitude_scale,
        fault_profile=opts.fault_profile,
        ramp_samples=opts.ramp_samples,
    )
    return SweepConfig(diagnosers=default_specs(opts.diagnosers), data=data, imports=opts.imports)


def store_dir_for(config: SweepConfig, out: Path) -> Path:
    """``out/store/<first 12 hex of the data hash>``: one store per data set-up."""
    return out / "store" / canonical_hash(config.data.store_key())[:12]


# ---- computation -------------------------------------------------------------------------------
def run(opts: LeaderboardOptions) -> SweepResults:
    """Run (or resume) the sweep of ``opts``; no output files, no printing."""
    config = build_config(opts)
    config.validate()
    return run_sweep(
        config,
        store_dir_for(config, opts.out),
        backend=opts.backend,
        n_workers=opts.workers,
        ray_address=opts.ray_address,
        progress=opts.progress,
        figure_cells=figure_cells(config) if opts.figures else (),
    )


# ---- CLI ---------------------------------------------------------------------------------------
def _csv_list(text: str) -> tuple[str, ...]:
    items = tuple(t.strip() for t in text.split(",") if t.strip())
    if not items:
        raise argparse.ArgumentTypeError(f"expected a comma-separated list, got {text!r}")
    return items


def _int_at_least(low: int) -> Callable[[str], int]:
    """An argparse type: an integer >= ``low``, refused by value otherwise."""

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if v < low:
            raise argparse.ArgumentTypeError(f"must be >= {low}, got {v}")
        return v

    return parse


_positive_int = _int_at_least(1)
_non_negative_int = _int_at_least(0)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m evaluation.leaderboard",
        description=(
            "Train diagnosers on healthy FCC-v0 episodes (training seeds 1000.., never tested), "
            "score them on every scenario over test seeds 0..N-1, and print a Markdown "
            "leaderboard (r_fd on healthy episodes; r_td and t_dt per fault; mean ± std over "
            "seeds; missed faults). Writes leaderboard.md/.csv, raw per-seed results and "
            "figures to --out. Re-running the same command resumes from the result store."
        ),
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help=f"fast check: the baselines ({', '.join(BASELINES)}), {QUICK_SEEDS} test seeds per "
        f"scenario, {QUICK_TRAIN_EPISODES} training episodes (explicit flags still win)",
    )
    p.add_argument(
        "--validation",
        action="store_true",
        help=f"the validation protocol hyperparameters are chosen on: seeds "
        f"{VALIDATION_SEED_BASE}.. ({VALIDATION_SEEDS} per scenario unless --seeds), faults at "
        f"{VALIDATION_FAULT_SCALE}x the paper's magnitudes, --out default {VALIDATION_OUT}; "
        "never the test seeds",
    )
    p.add_argument(
        "--import",
        dest="imports",
        type=_csv_list,
        action="append",
        default=[],
        metavar="MODULE[,MODULE]",
        help="import these modules first (repeatable): modules that register diagnosers of "
        "your own with @diagnosers.register, then named in --diagnosers. Imported (not run), "
        "from the current directory or the installed packages, here and in every worker",
    )
    p.add_argument(
        "--diagnosers",
        type=_csv_list,
        default=None,
        metavar="A,B",
        help="comma-separated registry names (default: every registered diagnoser; "
        "--quick: the baselines)",
    )
    p.add_argument(
        "--scenarios",
        type=_csv_list,
        default=None,
        metavar="S,...",
        help="comma-separated scenarios, from nominal,f1,f2,f3,f4 (default: all); with "
        "--external, test-file names",
    )
    p.add_argument(
        "--seeds",
        type=_positive_int,
        default=None,
        metavar="N",
        help=f"test seeds per scenario, 0..N-1 (default {DEFAULT_SEEDS}; --quick {QUICK_SEEDS}; "
        f"--validation {VALIDATION_SEEDS}, from {VALIDATION_SEED_BASE})",
    )
    p.add_argument(
        "--train-episodes",
        type=_positive_int,
        default=None,
        metavar="N",
        help=f"healthy training episodes, seeds {TRAIN_SEED_BASE}.. (default "
        f"{DEFAULT_TRAIN_EPISODES}; --quick {QUICK_TRAIN_EPISODES}); with --track, every track's "
        "(default 9, --quick 3)",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        metavar="DIR",
        help=f"output directory (default {DEFAULT_OUT}; --validation {VALIDATION_OUT})",
    )
    p.add_argument(
        "--backend",
        choices=BACKENDS,
        default="local",
        help="local: process pool on this machine (default); ray: Ray tasks (needs the ray extra)",
    )
    p.add_argument(
        "--ray-address",
        default=None,
        metavar="ADDR",
        help="address of a running Ray cluster for --backend ray (default: start a local one)",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help="worker processes (default: all cores; 0 runs in this process)",
    )
    p.add_argument(
        "--n-samples",
        type=_positive_int,
        default=4000,
        metavar="T",
        help="samples per simulated episode (default 4000, the paper's horizon)",
    )
    p.add_argument(
        "--fault-time",
        type=int,
        default=None,
        metavar="K",
        help="onset sample of every fault (default: the paper's onsets 1900/1900/2020/2000)",
    )
    p.add_argument(
        "--fault-profile",
        choices=("abrupt", "incipient"),
        default="abrupt",
        help="abrupt: the parameter jumps at the onset (default, the paper's); incipient: it "
        "ramps linearly to the full magnitude over --ramp-samples",
    )
    p.add_argument(
        "--ramp-samples",
        type=_positive_int,
        default=None,
        metavar="N",
        help="samples an incipient fault takes to reach its magnitude (default 500)",
    )
    p.add_argument(
        "--external",
        type=Path,
        default=None,
        metavar="DIR",
        help="score recorded data in DIR instead of simulated episodes: a directory with a "
        "dataset.json manifest (see evaluation.external.load_manifest) or the Santander FCCU "
        "data set (layout of shared/data/fccu-santander-mlpse); --seeds is ignored",
    )
    p.add_argument(
        "--track",
        metavar="NAME[,NAME...]",
        help=(
            "benchmark v2: run the named tracks (paper, small, incipient, noisy, uncertain, "
            "random, or all) with the physical-limit and measured-input reference rows and 95%% "
            "bootstrap intervals; writes <out>/<track>/ and <out>/summary.md (default --out "
            "results/tracks). With --quick: the baselines on 6 healthy and 3 faulty episodes per "
            "fault"
        ),
    )
    p.add_argument(
        "--test-seed-start",
        type=_non_negative_int,
        default=None,
        metavar="N",
        help=(
            "with --track: score every track on test seeds from N instead of 0 (a private range "
            "no tuning loop has seen, e.g. 100000; the training and validation seeds and the "
            "trained models stay the same). It must keep clear of the training (1000..) and "
            "validation (5000..) seeds"
        ),
    )
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def check_out_dir(out: Path) -> None:
    """Refuse an output directory that is, or lies under, an existing non-directory."""
    for p in (out, *out.parents):
        if p.exists():
            if not p.is_dir():
                where = "is" if p == out else f"lies under {str(p)!r}, which is"
                raise ValueError(
                    f"--out {str(out)!r} {where} a regular file, not a directory; "
                    "choose another output directory"
                )
            return


def _check_backend(backend: str) -> None:
    """``--backend ray`` needs Ray: say so before any work, not in a traceback."""
    if backend == "ray":
        try:
            import ray  # noqa: F401
        except ImportError:
            raise ValueError(
                "--backend ray needs Ray, which is not installed: "
                "pip install 'fcc-fault-diagnosis[ray]', or use --backend local"
            ) from None


def _store_failure(parser: argparse.ArgumentParser, e: Exception) -> NoReturn:
    """Exit on a store or run failure; suggest re-running only where it can succeed."""
    from evaluation.store import StoreError

    if isinstance(e, StoreError):  # a re-run meets the same file: the message says what to do
        parser.exit(1, f"{parser.prog}: {e}\n")
    parser.exit(1, f"{parser.prog}: {e}\nFinished cells are stored; re-run to resume.\n")


def resolve_options(
    args: argparse.Namespace, parser: argparse.ArgumentParser
) -> LeaderboardOptions:
    """Fill defaults (``--quick`` or full) and check names against the allowed sets."""
    from diagnosers import available

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
        if args.external is not None:  # recorded data have no labelled training faults
            from diagnosers import diagnoser_class

            diags = tuple(d for d in diags if not diagnoser_class(d).isolates)
    unknown = [d for d in diags if d not in avail]
    if unknown:
        parser.error(f"unknown diagnoser(s) {unknown}. Available: {avail}")
    if args.external is not None:
        from evaluation.external import load_external

        try:
            allowed = [tf.key for tf in load_external(args.external)[0].test_files]
        except ValueError as e:
            parser.error(f"--external {args.external}: {e}")
    else:
        import fcc_env

        allowed = list(fcc_env.SCENARIOS)
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
    try:
        _check_backend(args.backend)
        check_out_dir(args.out or (VALIDATION_OUT if args.validation else DEFAULT_OUT))
    except ValueError as e:
        parser.error(str(e))
    if args.validation:
        seeds = args.seeds or VALIDATION_SEEDS
    else:
        seeds = args.seeds or (QUICK_SEEDS if args.quick else DEFAULT_SEEDS)
    train = args.train_episodes or (QUICK_TRAIN_EPISODES if args.quick else DEFAULT_TRAIN_EPISODES)
    return LeaderboardOptions(
        diagnosers=diags,
        scenarios=scenarios,
        seeds=seeds,
        train_episodes=train,
        out=args.out or (VALIDATION_OUT if args.validation else DEFAULT_OUT),
        backend=args.backend,
        workers=args.workers,
        ray_address=args.ray_address,
        n_samples=args.n_samples,
        fault_time=args.fault_time,
        external=args.external,
        figures=not args.no_figures,
        progress=not args.no_progress,
        seed_base=VALIDATION_SEED_BASE if args.validation else 0,
        fault_magnitude_scale=VALIDATION_FAULT_SCALE if args.validation else 1.0,
        fault_profile=args.fault_profile,
        ramp_samples=args.ramp_samples,
        imports=_imports(args),
    )


def _imports(args: argparse.Namespace) -> tuple[str, ...]:
    """The ``--import`` modules, flattened, in order, without repeats."""
    return tuple(dict.fromkeys(m for group in args.imports for m in group))


def import_user_modules(args: argparse.Namespace, parser: argparse.ArgumentParser) -> None:
    """Import the ``--import`` modules, as ``python -m`` would find them: the current directory
    first (a console script does not put it on ``sys.path``; local workers inherit the path)."""
    modules = _imports(args)
    if not modules:
        return
    cwd = os.getcwd()
    if cwd not in sys.path and "" not in sys.path:
        sys.path.insert(0, cwd)
    try:
        import_modules(modules)
    except ValueError as e:
        parser.error(f"--import: {e}")


#: Options of the paper leaderboard that a track fixes itself, with their "not given" value:
#: with ``--track`` they are refused rather than silently ignored.
_NOT_FOR_TRACKS: dict[str, Any] = {
    "validation": False,
    "scenarios": None,
    "seeds": None,
    "n_samples": 4000,
    "fault_time": None,
    "fault_profile": "abrupt",
    "ramp_samples": None,
    "external": None,
}


def track_options(
    args: argparse.Namespace, parser: argparse.ArgumentParser, tracks: Sequence[Track]
) -> tuple[Track, ...]:
    """The tracks as ``--quick``, ``--train-episodes`` and ``--test-seed-start`` change them
    (explicit flags win).

    ``--train-episodes N`` gives every track N healthy training episodes (a data-rich run of the
    same test episodes; the published tracks train on 9). ``--test-seed-start N`` moves every
    track's test episodes to seeds N.. (a replication on seeds nobody has read; the models,
    trained on the training seeds, are the same). Options that a track defines for itself (its
    scenarios, seeds, horizon, fault settings) are refused by name.
    """
    for dest, unset in _NOT_FOR_TRACKS.items():
        if getattr(args, dest) != unset:
            flag = "--" + dest.replace("_", "-")
            parser.error(
                f"{flag} applies to the paper leaderboard, not to --track: a track fixes its own "
                "scenarios, seeds, horizon and fault settings (see evaluation.tracks); allowed "
                "with --track: --quick, --train-episodes, --test-seed-start, --diagnosers, --out, "
                "--backend, "
                "--workers, --ray-address, --import, --no-figures, --no-progress"
            )
    out = tuple(tracks)
    if args.quick:
        out = tuple(t.replace(n_healthy=6, n_faulty=3, n_train=3) for t in out)
    if args.train_episodes is not None:
        out = tuple(t.replace(n_train=args.train_episodes) for t in out)
    if args.test_seed_start is not None:
        try:
            out = tuple(t.with_seeds(test=args.test_seed_start) for t in out)
        except ValueError as e:
            parser.error(f"--test-seed-start {args.test_seed_start}: {e}")
    return out


def _main_tracks(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """``--track``: benchmark v2 (see :mod:`evaluation.trackboard`)."""
    from evaluation.trackboard import run_track, write_summary, write_track
    from evaluation.trackboard import track_table as trackboard_table
    from evaluation.tracks import parse_tracks

    try:
        tracks = parse_tracks(args.track)
    except ValueError as e:
        parser.error(str(e))
    tracks = track_options(args, parser, tracks)
    from diagnosers import available

    names = args.diagnosers or (BASELINES if args.quick else tuple(available()))
    out = args.out or Path("results/tracks")
    try:
        _check_backend(args.backend)
        check_out_dir(out)
    except ValueError as e:
        parser.error(str(e))
    runs = []
    for track in tracks:
        try:
            run_ = run_track(
                track,
                names,
                out / track.name,
                backend=args.backend,
                workers=args.workers,
                ray_address=args.ray_address,
                progress=not args.no_progress,
                figures=not args.no_figures,
                model_cache=out / "models",
                imports=_imports(args),
            )
        except ValueError as e:
            parser.error(str(e))
        except RuntimeError as e:
            _store_failure(parser, e)
        write_track(run_, out / track.name)
        runs.append(run_)
        print(trackboard_table(run_))
        print(
            f"track {track.name}: {run_.wall_s:.1f} s ({run_.n_computed} cells computed, "
            f"{run_.n_reused} reused; {run_.n_trained} diagnosers trained, "
            f"{run_.n_reused_models} models reused from another track)",
            file=sys.stderr,
        )
    write_summary(runs, out)
    print((out / "summary.md").read_text())
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    import_user_modules(args, parser)  # before any name is resolved
    if args.track is not None:
        return _main_tracks(args, parser)
    opts = resolve_options(args, parser)
    t0 = time.perf_counter()
    try:
        results = run(opts)
    except ValueError as e:  # bad configuration: say what and exit like argparse does
        parser.error(str(e))
    except RuntimeError as e:  # a diagnoser failed to train or score: finished cells are kept
        _store_failure(parser, e)
    written = write_outputs(results, opts.out, figures=opts.figures)
    reference = reference_row(results.config)
    print(markdown_table(results.summary(), reference=reference), end="", flush=True)
    # stdout stays the bare table (to pipe or paste); its legend follows on stderr
    print(table_legend(sample_time(results)), file=sys.stderr)
    print(
        f"{results.n_computed} cells computed, {results.n_reused} reused, "
        f"{results.n_trained} diagnosers trained in {time.perf_counter() - t0:.1f} s; "
        f"wrote {len(written)} files to {opts.out}",
        file=sys.stderr,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
