"""The leaderboard's command line: its parser and the checks both modes share.

``python -m evaluation.leaderboard`` (or ``fcc-leaderboard``) runs the paper leaderboard
(:mod:`evaluation.leaderboard.paper`) or, with ``--track``, the benchmark tracks
(:mod:`evaluation.leaderboard.track_runs`); both parse with :func:`build_parser` and refuse a bad
``--out``, ``--backend`` or ``--import`` here, before any work.

This module imports nothing heavy (no torch, scipy, matplotlib, diagnoser registry), so that
``--help`` and a refused argument answer at once: the defaults the help text quotes are mirrored
below from the modules that own them (``tests/test_cli_polish.py`` pins each to its source), and
the registry and the result store are imported when a check needs them.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

from fcc_common.invocation import (
    check_out_path,
    command_parser,
    csv_list,
    import_from_cwd,
    out_path,
    user_modules,
)

__all__ = [
    "CELL_BYTES",
    "DEFAULT_OUT",
    "DEFAULT_SEEDS",
    "DEFAULT_TRAIN_EPISODES",
    "EXTERNAL_OUT",
    "HELP_DEFAULTS",
    "QUICK_SEEDS",
    "QUICK_TRAIN_EPISODES",
    "VALIDATION_FAULT_SCALE",
    "VALIDATION_OUT",
    "VALIDATION_SEEDS",
    "VALIDATION_SEED_BASE",
    "build_parser",
    "check_backend",
    "check_counts",
    "check_out_dir",
    "exit_on_failure",
    "import_user_modules",
    "user_imports",
]


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

#: The values the help text and ``--backend`` quote, by owning module; the owners import torch,
#: scipy or matplotlib, which ``--help`` must not wait for (for a dict, its keys).
#: The leaderboard's defaults (this module owns them; evaluation.leaderboard.paper imports them).
QUICK_SEEDS = 3
QUICK_TRAIN_EPISODES = 3
DEFAULT_SEEDS = 10
DEFAULT_TRAIN_EPISODES = 9  # lrgf-mem: 6 to train the models, 3 held out to calibrate
DEFAULT_OUT = Path("results/leaderboard")
#: --external: recorded data, scored into a folder of their own (not over the --quick tables)
EXTERNAL_OUT = Path("results/external")
#: --validation: seeds 5000.. (never the test seeds 0..), faults at 0.7x the paper's magnitudes.
VALIDATION_SEED_BASE = 5000
VALIDATION_SEEDS = 40
VALIDATION_FAULT_SCALE = 0.7
VALIDATION_OUT = Path("results/validation")

#: Values the help text and ``--backend`` quote whose owners import torch, scipy or matplotlib,
#: which ``--help`` must not wait for (a test checks each against its owner).
HELP_DEFAULTS: dict[str, dict[str, Any]] = {
    "evaluation.sweep.config": {"BASELINES": ("limits", "pca", "arx-band")},
    "evaluation.sweep.sources": {"TRAIN_SEED_BASE": 1000},
    "evaluation.sweep.backends": {"BACKENDS": ("local", "ray")},
    "evaluation.tracks.catalogue": {
        "TRACKS": (
            "paper",
            "small",
            "incipient",
            "noisy",
            "uncertain",
            "mismatch",
            "random",
            "closed",
            "closed-random",
            "regimes",
            "sensor",
            "actuator",
            "concurrent",
        )
    },
}
_D = {name: value for owned in HELP_DEFAULTS.values() for name, value in owned.items()}
BASELINES, BACKENDS, TRAIN_SEED_BASE = _D["BASELINES"], _D["BACKENDS"], _D["TRAIN_SEED_BASE"]

_DESCRIPTION = (
    "Train diagnosers on healthy FCC-v0 episodes (training seeds 1000.., never tested), "
    "score them on every scenario over test seeds 0..N-1, and print a Markdown "
    "leaderboard (r_fd on healthy episodes; r_td and t_dt per fault; mean ± std over "
    "seeds; missed faults) followed by its legend. Writes leaderboard.md/.csv, raw per-seed "
    "results and figures to --out. Re-running the same command resumes from the result store."
    "\n\nProgress and timings go to stderr, so `> table.md` keeps the table and its legend."
)
_EXAMPLES = (
    (
        "--quick",
        f"the baselines on {QUICK_SEEDS} test seeds per scenario, into {DEFAULT_OUT}",
    ),
    (
        "--diagnosers pca,lrgf-mem --scenarios nominal,f1 --seeds 5 --out results/two",
        "two diagnosers on the healthy plant and fault f1, 5 test seeds each",
    ),
    (
        "--import examples.cusum_diagnoser --diagnosers cusum-example --quick --out results/cusum",
        "a diagnoser of your own: examples/cusum_diagnoser.py registers it (run from the "
        "repository root)",
    ),
    ("--track all --quick", "every benchmark track, on fewer episodes, into results/tracks"),
    (
        "--task control --seeds 2 --diagnosers ''",
        "the control task's leaderboard (FCC-control-v0: returns in USD, trips, loss against "
        "the oracle); its options are python -m evaluation.control's (--task control --help)",
    ),
)


def build_parser() -> argparse.ArgumentParser:
    p = command_parser("evaluation.leaderboard", _DESCRIPTION, _EXAMPLES)
    p.add_argument(
        "--task",
        choices=("detection", "control"),
        default="detection",
        help="detection (default): the diagnosers' leaderboard; control: the control task's "
        "(what a supervisor, the oracle and the baselines earn on FCC-control-v0), with the "
        "options of python -m evaluation.control",
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
        type=csv_list,
        action="append",
        default=[],
        metavar="MODULE[,MODULE]",
        help="import these modules first (repeatable): modules that register diagnosers of "
        "your own with @diagnosers.register, then named in --diagnosers. Imported (not run), "
        "from the current directory or the installed packages, here and in every worker",
    )
    p.add_argument(
        "--diagnosers",
        type=csv_list,
        default=None,
        metavar="A,B",
        help="comma-separated registry names (default: every registered diagnoser; "
        "--quick: the baselines)",
    )
    p.add_argument(
        "--scenarios",
        type=csv_list,
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
        type=out_path,
        default=None,
        metavar="DIR",
        help=f"output directory (default {DEFAULT_OUT}; --validation {VALIDATION_OUT}; "
        f"--external {EXTERNAL_OUT})",
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
        "dataset.json manifest (see evaluation.sweep.external_data.load_manifest) or the Santander FCCU "
        "data set (the Santander et al. (2022) dataset's layout); --seeds is ignored",
    )
    p.add_argument(
        "--track",
        metavar="NAME[,NAME...]",
        help=(
            f"benchmark v2: run the named tracks ({', '.join(_D['TRACKS'])}, or all) with the physical-limit and measured-input reference rows and 95%% "
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
    """Refuse an output directory that is empty, is or lies under a regular file, or cannot be
    written (:func:`fcc_common.invocation.check_out_path`)."""
    check_out_path("--out", out)
    if out.exists() and not out.is_dir():
        raise ValueError(
            f"--out {str(out)!r} is a regular file, not a directory; choose another output "
            "directory"
        )


#: Bytes a test cell costs the driver while a sweep runs and reports (its record, its entries in
#: the work lists, its rows of results.csv/.json); a generous estimate, to refuse absurd counts
#: before any range of seeds is built, not to plan a run.
CELL_BYTES = 8 * 2**10


def check_counts(
    *,
    seeds: int | None,
    seed_base: int,
    train_episodes: int | None,
    n_samples: int,
    n_cells_per_seed: int,
) -> None:
    """Refuse counts that overlap another seed range or exceed the memory budget, before any
    range or list of seeds is built (``None``: not given, a default that is known to fit).

    Test seeds are ``seed_base..`` (0, or :data:`VALIDATION_SEED_BASE` with ``--validation``),
    training seeds :data:`TRAIN_SEED_BASE`.. and validation seeds :data:`VALIDATION_SEED_BASE`..;
    a training episode is held whole in a worker while it trains (budget:
    :data:`fcc_env.simulation.DEFAULT_MEMORY_BUDGET_BYTES`).
    """
    from fcc_env.simulation import DEFAULT_MEMORY_BUDGET_BYTES, check_memory

    ranges = (
        f"test seeds 0..{TRAIN_SEED_BASE - 1}, training seeds {TRAIN_SEED_BASE}.."
        f"{VALIDATION_SEED_BASE - 1}, validation seeds {VALIDATION_SEED_BASE}.."
    )
    if train_episodes is not None and TRAIN_SEED_BASE + train_episodes > VALIDATION_SEED_BASE:
        raise ValueError(
            f"--train-episodes {train_episodes} would use training seeds {TRAIN_SEED_BASE}.."
            f"{TRAIN_SEED_BASE + train_episodes - 1}, into the validation seeds "
            f"{VALIDATION_SEED_BASE}..; at most {VALIDATION_SEED_BASE - TRAIN_SEED_BASE} "
            f"({ranges})"
        )
    if seeds is not None and seed_base < TRAIN_SEED_BASE < seed_base + seeds:
        raise ValueError(
            f"--seeds {seeds} would use test seeds {seed_base}..{seed_base + seeds - 1}, into the "
            f"training seeds {TRAIN_SEED_BASE}..; at most {TRAIN_SEED_BASE - seed_base} ({ranges})"
        )
    if seeds is not None and seeds * n_cells_per_seed * CELL_BYTES > DEFAULT_MEMORY_BUDGET_BYTES:
        most = DEFAULT_MEMORY_BUDGET_BYTES // (n_cells_per_seed * CELL_BYTES)
        raise ValueError(
            f"--seeds {seeds} makes {seeds * n_cells_per_seed} cells ({n_cells_per_seed} per "
            f"seed), more than the memory budget of "
            f"{DEFAULT_MEMORY_BUDGET_BYTES / 2**30:g} GiB holds at about {CELL_BYTES // 1024} "
            f"KiB a cell: at most {most} seeds, or fewer diagnosers or scenarios per run"
        )
    # the arrays only: the process peaks higher (see check_memory's message)
    held = (
        (f"--train-episodes {train_episodes} x --n-samples {n_samples}", train_episodes),
        (f"--n-samples {n_samples}", 1),
    )
    for what, n in held:
        if n is None:
            continue
        try:
            check_memory(n, n_samples)
        except ValueError as e:
            raise ValueError(f"{what} (held by each worker): {e}") from None


def check_backend(backend: str) -> None:
    """``--backend ray`` needs Ray: say so before any work, not in a traceback."""
    if backend == "ray":
        try:
            import ray  # noqa: F401
        except ImportError:
            raise ValueError(
                "--backend ray needs Ray, which is not installed: "
                "pip install 'fcc-fault-diagnosis[ray]', or use --backend local"
            ) from None


#: Exceptions (by class name, Ray's included without importing Ray) of a worker that died rather
#: than of a task that raised: killed, out of memory, its node lost. Only these, and an
#: interruption, are cured by re-running.
_WORKER_DEATHS = frozenset(
    {
        "BrokenProcessPool",
        "WorkerCrashedError",
        "NodeDiedError",
        "LocalRayletDiedError",
        "OwnerDiedError",
        "ObjectLostError",
        "TaskCancelledError",
    }
)


def _worker_died(e: BaseException | None) -> bool:
    while e is not None:
        if type(e).__name__ in _WORKER_DEATHS:
            return True
        e = e.__cause__
    return False


def exit_on_failure(parser: argparse.ArgumentParser, e: BaseException) -> NoReturn:
    """Exit on an interruption, a store or a run failure; advise re-running only where it can
    succeed: after an interruption or a worker that died, not after a deterministic failure."""
    if isinstance(e, KeyboardInterrupt):
        parser.exit(
            130,
            f"{parser.prog}: interrupted; finished cells are stored: re-run the same command "
            "to resume\n",
        )
    if _worker_died(e):
        parser.exit(
            1,
            f"{parser.prog}: {e}\nA worker process died (killed, or out of memory); finished "
            "cells are stored: re-run the same command to resume (with fewer --workers if memory "
            "ran out).\n",
        )
    # a store error names the file and what to do; a diagnoser that raised raises again
    from evaluation.sweep.store import StoreError  # imported when a run has failed: see above

    advice = (
        ""
        if isinstance(e, StoreError)
        else "Finished cells are stored, but re-running fails the same way until the cause "
        "above is fixed (or the failing diagnoser is left out of --diagnosers).\n"
    )
    parser.exit(1, f"{parser.prog}: {e}\n{advice}")


def user_imports(args: argparse.Namespace) -> tuple[str, ...]:
    """The ``--import`` modules, flattened, in order, without repeats."""
    return user_modules(args.imports)


def import_user_modules(args: argparse.Namespace, parser: argparse.ArgumentParser) -> None:
    """Import the ``--import`` modules, as ``python -m`` would find them: the current directory
    first (a console script does not put it on ``sys.path``; local workers inherit the path)."""
    modules = user_imports(args)
    if not modules:
        return
    from diagnosers.registry import import_modules  # the registry imports torch: see above

    try:
        import_from_cwd(modules, import_modules)
    except ValueError as e:
        parser.error(f"--import: {e}")
