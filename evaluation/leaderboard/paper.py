"""The paper leaderboard as a library: options, the sweep they describe, and running it.

:class:`LeaderboardOptions` are the resolved command-line options; :func:`build_config` turns
them into a :class:`~evaluation.sweep.SweepConfig` (simulated ``FCC-v0`` episodes, or a recorded
dataset with ``external``), and :func:`run` runs or resumes it without printing or writing
tables (:mod:`evaluation.reports.outputs` writes them; :mod:`evaluation.leaderboard.command`
is the command line).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

from evaluation.reports.outputs import figure_cells
from evaluation.sweep.config import DiagnoserSpec, SweepConfig, SweepResults, default_specs
from evaluation.sweep.dataset_loaders import load_external
from evaluation.sweep.runner import run_sweep
from evaluation.sweep.sources import TRAIN_SEED_BASE, SimulatedData
from evaluation.sweep.store import canonical_hash
from fcc_env.scenarios import FaultSpec

__all__ = [
    "LeaderboardOptions",
    "build_config",
    "run",
    "store_dir_for",
]


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
    fault: FaultSpec = field(default_factory=FaultSpec)
    external: Path | None = None
    figures: bool = True
    progress: bool = True
    seed_base: int = 0
    imports: tuple[str, ...] = ()


def build_config(opts: LeaderboardOptions) -> SweepConfig:
    """The sweep the options describe (validated by :func:`run_sweep`)."""
    if opts.external is not None:
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
        fault=opts.fault,
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
        relation_cache=opts.out / "relations",
    )
