"""Command line: ``python -m evaluation.discover (--data PATH.csv | --external DIR | --manifest
DIR/dataset.json) --out DIR [--candidates id,id] [--train-fraction 0.6] [--max-effects 3]
[--alpha 0.01] [--drift auto|estimate|off] [--drift-fit joint|fixed] [--no-plots] [--progress | --no-progress]``.

``--data`` reads a dataset with this project's JSON sidecar (CSV or Parquet). ``--external`` and
``--manifest`` read a user's directory through its manifest
(:func:`evaluation.sweep.external_data.load_manifest`: inputs, outputs, sample time, the healthy
``train_files``). When the manifest's channels include those of the FCC physics model
(:class:`~evaluation.discover.physics_model.PhysicsModel`) it is used; otherwise the declared model is
a linear ARX model of each output from the manifest's inputs
(:class:`~evaluation.discover.arx.ARXModel`), whose candidates are missing measured inputs.
A progress bar per round (the candidates fitted) goes to standard error when it is a terminal,
or with ``--progress``; ``--no-progress`` turns it off.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from evaluation.discover.arx import ARXModel
from evaluation.discover.data import from_external
from evaluation.discover.drift_joint import DRIFT_FITS
from evaluation.discover.form_search import FormSearch
from evaluation.discover.loop import discover
from evaluation.discover.physics_model import (
    PHYSICS_INPUT_CHANNELS,
    PHYSICS_OUTPUT_CHANNELS,
    PhysicsModel,
    declared_from_report,
)
from evaluation.discover.report import REPORT_FILE
from evaluation.sweep.dataset_loaders import load_manifest
from fcc_common.invocation import check_out_path, command_parser, run_command
from fcc_common.progress import add_progress_flag
from fcc_common.safe_files import read_json

__all__ = ["main"]


def _source(args: argparse.Namespace) -> tuple[Any, Any]:
    """``(data, model)``: the dataset path and the default model, or a manifest's records and
    the physics model (if its channels allow) or an ARX model of its outputs from its inputs."""
    if args.data is not None:
        return args.data, None
    ext, _ = load_manifest(args.external if args.external is not None else args.manifest)
    data = from_external(ext)
    needed = {"cmd_u_F", "cmd_R_ar", *PHYSICS_INPUT_CHANNELS, *PHYSICS_OUTPUT_CHANNELS}
    if needed <= set(data.channels):
        return data, None
    return data, ARXModel({o: tuple(ext.inputs) for o in ext.outputs})


def main(argv: Sequence[str] | None = None) -> int:
    parser = command_parser(
        "evaluation.discover",
        "Find the effect the declared FCC model lacks in measured data, add it, and "
        "report the held-out error before and after (DIR/report.json + plots).",
        (
            (
                "--data data/f1.csv --out results/discover",
                "a dataset written by fcc_env.generate (CSV or Parquet, with its .json sidecar)",
            ),
            (
                "--external my_unit/ --out results/my_unit --max-effects 2",
                "your own data: a directory with a dataset.json manifest; at most two effects",
            ),
            (
                "--data data/f1.csv --out results/d --candidates heat_loss:stage1 --no-plots",
                "test one candidate effect, without figures",
            ),
        ),
    )
    src = parser.add_mutually_exclusive_group(required=True)
    src.add_argument("--data", help="dataset .csv/.parquet with its .json sidecar (same stem)")
    src.add_argument("--external", metavar="DIR", help="data directory with a dataset.json")
    src.add_argument("--manifest", metavar="FILE", help="a manifest file (dataset.json format)")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--candidates", default=None, help="comma-separated candidate ids (all)")
    parser.add_argument("--train-fraction", type=float, default=0.6, help="in (0.2, 0.9); 0.6")
    parser.add_argument("--max-effects", type=int, default=3, help="0-10; 3")
    parser.add_argument("--alpha", type=float, default=0.01, help="family-wise level per round")
    parser.add_argument("--no-plots", action="store_true")
    parser.add_argument(
        "--accept",
        metavar="REPORT",
        help="a previous report.json: its effects and forms become part of the declared model",
    )
    parser.add_argument(
        "--forms",
        choices=("auto", "always", "never"),
        default="auto",
        help="search for a form when structure remains (auto), always, or never",
    )
    parser.add_argument("--max-terms", type=int, default=3, help="terms of a form, 1-5; 3")
    parser.add_argument(
        "--drift",
        choices=("auto", "estimate", "off"),
        default="auto",
        help="estimate the unmeasured feed-coking drift first and feed it to the model: on "
        "closed-loop data (auto), always, or never",
    )
    parser.add_argument(
        "--drift-fit",
        choices=DRIFT_FITS,
        default="joint",
        help="the drift estimate's level and trend fitted with every candidate (joint) or the "
        "estimate fed as it is (fixed)",
    )
    add_progress_flag(parser)
    return run_command(parser, _discover, argv)


def _discover(args: argparse.Namespace) -> int:
    """The work of :func:`main`: its failures are refused by :func:`run_command`."""
    check_out_path("--out", args.out)
    cands = None
    if args.candidates:
        cands = [c.strip() for c in args.candidates.split(",") if c.strip()]
    data, model = _source(args)
    if args.accept is not None:
        if model is not None:
            raise ValueError("--accept needs the FCC physics model (its channels in the data)")
        model = PhysicsModel(declared=declared_from_report(read_json(args.accept)))
    report = discover(
        data,
        model=model,
        candidates=cands,
        train_fraction=args.train_fraction,
        max_effects=args.max_effects,
        alpha=args.alpha,
        out_dir=args.out,
        plots=not args.no_plots,
        progress=args.progress,
        forms=args.forms,
        form_search=FormSearch(max_terms=args.max_terms),
        drift=args.drift,
        drift_fit=args.drift_fit,
    )
    for e in report.effects:
        if e.equation is not None:
            print(f"form {e.equation['text']}  (enters {e.equation['enters']})")
        else:
            print(f"effect {e.id}: {dict(e.params)} (95% CI {dict(e.ci95)})")
    if not report.effects:
        print("no significant effect found")
    for c in report.channels:
        print(f"  {c:6s} held-out RMSE {report.rmse_before[c]:.3f} -> {report.rmse_after[c]:.3f}")
    if report.drift is not None:
        for i, ep in enumerate(report.drift["episodes"][:5]):
            print(
                f"  drift (estimated f_coke, episode {i}): mean {ep['mean']:.4f} "
                f"range {ep['min']:.4f}-{ep['max']:.4f}, trend {ep['trend_per_day']:+.4f}/day"
            )
        line = report.drift.get("line")
        if line is not None:
            print(
                f"  drift line fitted with the effects: level {line['level']:+.4f}, "
                f"trend {line['trend_per_day']:+.4f}/day"
            )
    print(f"unexplained structure: {report.unexplained} {list(report.unexplained_channels)}")
    print(f"wrote {Path(args.out) / REPORT_FILE} in {report.elapsed_s:.1f} s")
    return 0
