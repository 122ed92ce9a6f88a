"""``python -m evaluation.leaderboard --track NAME[,NAME]``: the benchmark tracks.

Each track (:mod:`evaluation.tracks`) is run by :func:`evaluation.tracks.board.run_track` into
``--out/<track>`` (default ``results/tracks``), then a summary over the tracks is written.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from diagnosers.registry import available
from evaluation.leaderboard.arguments import (
    check_backend,
    check_counts,
    check_out_dir,
    exit_on_failure,
    user_imports,
)
from evaluation.sweep.config import BASELINES
from evaluation.tracks.board import run_track
from evaluation.tracks.board_tables import track_table as trackboard_table
from evaluation.tracks.board_tables import write_summary, write_track
from evaluation.tracks.catalogue import parse_tracks
from evaluation.tracks.track import Track

__all__ = ["main_tracks", "track_options"]


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


def main_tracks(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """``--track``: benchmark v2 (see :mod:`evaluation.tracks.board`)."""
    try:
        tracks = parse_tracks(args.track)
    except ValueError as e:
        parser.error(str(e))
    try:  # before a track builds its ranges of seeds
        check_counts(
            seeds=None,
            seed_base=0,
            train_episodes=args.train_episodes,
            n_samples=4000,
            n_cells_per_seed=1,
        )
    except ValueError as e:
        parser.error(str(e))
    tracks = track_options(args, parser, tracks)
    names = args.diagnosers or (BASELINES if args.quick else tuple(available()))
    out = args.out or Path("results/tracks")
    try:
        check_backend(args.backend)
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
                relation_cache=out / "relations",
                imports=user_imports(args),
            )
        except ValueError as e:
            parser.error(str(e))
        except (RuntimeError, KeyboardInterrupt) as e:
            exit_on_failure(parser, e)
        write_track(run_, out / track.name)
        runs.append(run_)
        print(trackboard_table(run_))
        print(
            f"track {track.name}: {run_.wall_s:.1f} s ({run_.n_computed} cells computed, "
            f"{run_.n_reused} reused; {run_.n_reference_computed} reference-row cells "
            f"computed; {run_.n_trained} diagnosers trained, "
            f"{run_.n_reused_models} models reused from another track)",
            file=sys.stderr,
        )
    write_summary(runs, out)
    print((out / "summary.md").read_text())
    return 0
