"""The loop's result: a frozen :class:`DiscoveryReport`, its JSON form, the residual tests, plots.

``DIR/report.json`` holds :meth:`DiscoveryReport.to_json` (written atomically): ``effects`` (id,
parameters with standard errors and 95 % intervals), ``rmse_before``/``rmse_after`` (held-out,
per channel), ``unexplained``, the test statistics before and after, every round's candidate
table; ``DIR/residuals.png``/``DIR/autocorrelation.png`` show episode 0.
"""

from __future__ import annotations

import copy
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from evaluation.discover import residual_tests as rt
from evaluation.discover.base import Candidate
from evaluation.discover.data import MeasuredData
from fcc_common.io import atomic_write_json

__all__ = [
    "REPORT_FILE",
    "AcceptedEffect",
    "DiscoveryReport",
    "finite_or_none",
    "named",
    "per_channel",
    "plot_residuals",
    "residual_diagnostics",
]

REPORT_FILE = "report.json"


def finite_or_none(v: float) -> float | None:
    """``float(v)``, or ``None`` when it is NaN or infinite (strict JSON)."""
    v = float(v)
    return v if math.isfinite(v) else None


def named(cand: Candidate, values: np.ndarray) -> dict[str, float | None]:
    """``{parameter name: value}`` of a candidate's parameter vector."""
    return {p.name: finite_or_none(v) for p, v in zip(cand.params, values, strict=True)}


def per_channel(chans: Sequence[str], v: np.ndarray) -> dict[str, float | None]:
    """``{channel: value}`` of a per-channel vector."""
    return {c: finite_or_none(x) for c, x in zip(chans, v, strict=True)}


@dataclass(frozen=True, kw_only=True)
class AcceptedEffect:
    """One effect the loop added: estimates, standard errors, 95 % intervals, held-out stats."""

    id: str
    params: Mapping[str, float | None]
    stderr: Mapping[str, float | None]
    ci95: Mapping[str, list[float | None]]
    round: int  # the round that added it
    heldout: Mapping[str, float | None]  # score, rel_reduction, p_value when it was added
    explains_structure: bool  # False when structure remains after the loop
    #: a form's readable equation (``text``, ``enters``, ``unit``, ``terms``); None: library
    equation: Mapping[str, Any] | None = None
    #: a form's definition (:func:`evaluation.discover.terms.form_to_json`): what accepting reads
    form: Mapping[str, Any] | None = None

    def to_json(self) -> dict[str, Any]:
        extra: dict[str, Any] = {}
        if self.equation is not None:
            extra = {"equation": copy.deepcopy(dict(self.equation)), "form": dict(self.form or {})}
        return {
            "id": self.id,
            "params": dict(self.params),
            "stderr": dict(self.stderr),
            "ci95": {k: list(v) for k, v in self.ci95.items()},
            "round": self.round,
            "heldout": dict(self.heldout),
            "explains_structure": self.explains_structure,
            **extra,
        }


@dataclass(frozen=True, kw_only=True)
class DiscoveryReport:
    """What :func:`~evaluation.discover.discover` found, with typed fields.

    Per-channel values are ``{channel: value}`` mappings (``None`` for a non-finite value).
    :meth:`to_json` gives the plain dict that ``report.json`` holds, key for key.
    """

    tool: str = "evaluation.discover"
    model: str
    data: str
    n_episodes: int
    n_samples: int
    n_train: int
    channels: tuple[str, ...]
    effects: tuple[AcceptedEffect, ...]
    rmse_before: Mapping[str, float | None]  # held-out
    rmse_after: Mapping[str, float | None]
    rmse_train_before: Mapping[str, float | None]
    rmse_train_after: Mapping[str, float | None]
    noise_std_estimate: Mapping[str, float | None]
    unexplained: bool
    unexplained_channels: tuple[str, ...]
    structure_before: Mapping[str, Mapping[str, float | None]]  # "ratio", "lf" per channel
    structure_after: Mapping[str, Mapping[str, float | None]]
    structure_limits: Mapping[str, float]
    tests_before: Mapping[str, Any]  # evaluation.discover.residual_tests.diagnose per channel
    tests_after: Mapping[str, Any]
    rounds: tuple[Mapping[str, Any], ...]  # every round's candidate table
    skipped_candidates: Mapping[str, str]
    settings: Mapping[str, Any]
    note: str | None = None
    elapsed_s: float
    plots: tuple[str, ...] | None = None  # file names in the output folder
    #: the estimated feed-coking drift (:meth:`evaluation.discover.drift.DriftEstimate.summary`;
    #: with the joint fit also ``line``: :func:`evaluation.discover.drift_joint.line_summary`)
    drift: Mapping[str, Any] | None = None

    def to_json(self) -> dict[str, Any]:
        """The report as the plain JSON-ready dict of ``report.json`` (a fresh copy)."""
        out: dict[str, Any] = {
            "tool": self.tool,
            "model": self.model,
            "data": self.data,
            "n_episodes": self.n_episodes,
            "n_samples": self.n_samples,
            "n_train": self.n_train,
            "channels": list(self.channels),
            "effects": [e.to_json() for e in self.effects],
        }
        for key in (
            "rmse_before",
            "rmse_after",
            "rmse_train_before",
            "rmse_train_after",
            "noise_std_estimate",
        ):
            out[key] = dict(getattr(self, key))
        out["unexplained"] = self.unexplained
        out["unexplained_channels"] = list(self.unexplained_channels)
        out["structure_before"] = {k: dict(v) for k, v in self.structure_before.items()}
        out["structure_after"] = {k: dict(v) for k, v in self.structure_after.items()}
        out["structure_limits"] = dict(self.structure_limits)
        out["tests_before"] = copy.deepcopy(dict(self.tests_before))
        out["tests_after"] = copy.deepcopy(dict(self.tests_after))
        out["rounds"] = copy.deepcopy([dict(r) for r in self.rounds])
        out["skipped_candidates"] = dict(self.skipped_candidates)
        out["settings"] = dict(self.settings)
        if self.note is not None:
            out["note"] = self.note
        out["elapsed_s"] = self.elapsed_s
        if self.plots is not None:
            out["plots"] = list(self.plots)
        if self.drift is not None:
            out["drift"] = copy.deepcopy(dict(self.drift))
        return out

    def write(self, out_dir: str | os.PathLike) -> Path:
        """Write :meth:`to_json` to ``out_dir/report.json`` atomically; returns the path."""
        return atomic_write_json(Path(out_dir) / REPORT_FILE, self.to_json())


def residual_diagnostics(
    data: MeasuredData,
    E: np.ndarray,
    n_train: int,
    chans: Sequence[str],
    others: Sequence[str],
    max_lag: int,
) -> dict[str, Any]:
    """Residual tests of episode 0's held-out part, per channel."""
    out = {}
    for j, c in enumerate(chans):
        e = E[0, n_train:, j]
        sig = {
            o: data.channels[o][0, n_train:]
            for o in others
            if np.ptp(data.channels[o][0, n_train:]) > 0
        }
        sig.update({o: E[0, n_train:, i] for i, o in enumerate(chans) if o != c})
        out[c] = rt.diagnose(e, sig, sample_time_s=data.sample_time_s, max_lag=max_lag)
    return out


def plot_residuals(
    out: Path,
    data: MeasuredData,
    E0: np.ndarray,
    E1: np.ndarray,
    n_train: int,
    chans: Sequence[str],
    max_lag: int,
) -> list[str]:
    t_h = data.t_s / 3600.0
    fig = Figure(figsize=(10, 2.0 * len(chans)), constrained_layout=True)
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(chans), 1, sharex=True, squeeze=False)[:, 0]
    for j, c in enumerate(chans):
        ax = axes[j]
        ax.plot(t_h, E0[0, :, j], lw=0.6, color="tab:red", label="before")
        ax.plot(t_h, E1[0, :, j], lw=0.6, color="tab:blue", label="after")
        ax.axvline(t_h[n_train], color="k", ls="--", lw=0.8)
        ax.set_ylabel(f"{c} residual")
    axes[0].legend(loc="upper left", fontsize=8)
    axes[0].set_title("Simulation residuals (episode 0); dashed: start of held-out part")
    axes[-1].set_xlabel("time [h]")
    p1 = out / "residuals.png"
    fig.savefig(p1, dpi=90)
    fig2 = Figure(figsize=(10, 2.0 * len(chans)), constrained_layout=True)
    FigureCanvasAgg(fig2)
    axes = fig2.subplots(len(chans), 1, sharex=True, squeeze=False)[:, 0]
    for j, c in enumerate(chans):
        for E, col, lab in ((E0, "tab:red", "before"), (E1, "tab:blue", "after")):
            r = rt.autocorrelation(E[0, n_train:, j], max_lag)
            axes[j].plot(r.lags, r.values, "o-", ms=3, color=col, label=lab)
            lim = r.limit
        axes[j].axhspan(-lim, lim, color="0.85")
        axes[j].set_ylabel(f"{c} ACF")
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel("lag [samples]")
    p2 = out / "autocorrelation.png"
    fig2.savefig(p2, dpi=90)
    return [p1.name, p2.name]
