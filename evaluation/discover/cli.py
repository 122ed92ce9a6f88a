"""Command line: ``python -m evaluation.discover --data PATH.csv --out DIR [--candidates id,id]
[--train-fraction 0.6] [--max-effects 3] [--alpha 0.01] [--no-plots]``."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from evaluation.discover.loop import discover
from evaluation.discover.report import REPORT_FILE

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m evaluation.discover",
        description="Find the effect the declared FCC model lacks in measured data, add it, and "
        "report the held-out error before and after (DIR/report.json + plots).",
    )
    parser.add_argument("--data", required=True, help="dataset CSV (sidecar: same stem .json)")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--candidates", default=None, help="comma-separated candidate ids (all)")
    parser.add_argument("--train-fraction", type=float, default=0.6, help="in (0.2, 0.9); 0.6")
    parser.add_argument("--max-effects", type=int, default=3, help="0-10; 3")
    parser.add_argument("--alpha", type=float, default=0.01, help="family-wise level per round")
    parser.add_argument("--no-plots", action="store_true")
    args = parser.parse_args(argv)
    cands = None
    if args.candidates:
        cands = [c.strip() for c in args.candidates.split(",") if c.strip()]
    try:
        report = discover(
            args.data,
            candidates=cands,
            train_fraction=args.train_fraction,
            max_effects=args.max_effects,
            alpha=args.alpha,
            out_dir=args.out,
            plots=not args.no_plots,
        )
    except ValueError as e:
        parser.error(str(e))
    for e in report.effects:
        print(f"effect {e.id}: {dict(e.params)} (95% CI {dict(e.ci95)})")
    if not report.effects:
        print("no significant effect found")
    for c in report.channels:
        print(f"  {c:6s} held-out RMSE {report.rmse_before[c]:.3f} -> {report.rmse_after[c]:.3f}")
    print(f"unexplained structure: {report.unexplained} {list(report.unexplained_channels)}")
    print(f"wrote {Path(args.out) / REPORT_FILE} in {report.elapsed_s:.1f} s")
    return 0
