"""Simulate the healthy plant and each fault on one seed and plot them: ``python -m fcc_env.demo``."""

from __future__ import annotations

import argparse
from pathlib import Path

import fcc_env
from fcc_common.invocation import check_out_path, command_parser, run_command
from fcc_env.plotting import plot_scenarios


def main(argv: list[str] | None = None) -> int:
    parser = command_parser(
        "fcc_env.demo",
        "Simulate the healthy plant and each fault on one seed and plot them.",
        (
            ("", "seed 0, into results/demo/scenarios.png"),
            ("--seed 3 --out results/demo3", "another seed, into results/demo3/scenarios.png"),
        ),
    )
    parser.add_argument("--out", default="results/demo", help="output folder (results/demo)")
    parser.add_argument("--seed", type=int, default=0, help="episode seed (0)")
    return run_command(parser, _demo, argv)


def _demo(args: argparse.Namespace) -> int:
    """The work of :func:`main`: its failures are refused by :func:`run_command`."""
    check_out_path("--out", args.out)
    episodes, onsets = {}, {}
    for scenario in fcc_env.scenario_names():
        b = fcc_env.simulate_episodes([args.seed], fault=fcc_env.FaultSpec(scenario=scenario))
        episodes[scenario] = b.observations[0]
        onsets[scenario] = b.fault_onsets[0]
    path = plot_scenarios(episodes, onsets, b.sample_time_s, Path(args.out) / "scenarios.png")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
