"""Isolability at the physical limit: which faults the Table 1 measurements can tell apart, and how soon.

Like the physical-limit row (:mod:`evaluation.tracks.oracle`) this knows what no diagnoser may: the
healthy plant's noise-free output of the same seed (:meth:`TrackData.reference`), and it can
simulate any fault hypothesis on that seed. On the five temperatures T_rx, T_rg1, T_rg2, T_d1,
T_dg, each normalised by its noise standard deviation σ (times the track's noise scale):

* **signature** of fault ``f`` on seed ``s``: ``s_f(k) = (y_f,clean(k) − y_ref(k)) / σ`` from the
  onset on (noise-free: what the fault alone does to the measurements);
* **direction angle** between two faults: the angle between their mean signature vectors over
  the first ``window`` samples after the onset, averaged over seeds (:func:`direction_angles`);
* **separation time** of a true fault ``i`` from a hypothesis ``j`` (:func:`separation_times`):
  the measured residual ``r(k) = (y(k) − y_ref(k)) / σ`` (noise included) is compared with both
  hypotheses' signatures on the same seed and onset, each with its own unknown non-negative size
  (least squares, so the test does not know the magnitude). The GLR statistic after ``n``
  samples is ``Λ_ij(n) = (SS_j(n) − SS_i(n)) / 2``, ``SS_h(n) = min_{a≥0} Σ_{k<n} ‖r − a s_h‖²``;
  ``i`` is separated from ``j`` at the first ``n`` from which ``Λ_ij ≥ log(1/α)`` holds up to the
  analysis horizon. ``α = 0.01``: under white Gaussian noise a Wald-type bound on the chance of
  preferring the wrong hypothesis at that point. The result is the median over seeds, with the
  share of seeds separated within the horizon.

Run ``python -m evaluation.isolation.isolability --track paper`` for the tables.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from evaluation.tracks.catalogue import TRACKS
from evaluation.tracks.track_data import TrackData
from fcc_common.invocation import command_parser, run_command
from fcc_common.validation import Integer, Real, check
from fcc_env.params import MEASUREMENT_NAMES, MEASUREMENTS

__all__ = [
    "CHANNELS",
    "Isolability",
    "direction_angles",
    "isolability",
    "isolability_markdown",
    "separation_times",
    "signatures",
]

#: the temperatures of the analysis (those of the physical-limit row)
CHANNELS: tuple[str, ...] = ("T_rx", "T_rg1", "T_rg2", "T_d1", "T_dg")


def _noise(data: TrackData) -> tuple[np.ndarray, np.ndarray]:
    idx = np.array([MEASUREMENT_NAMES.index(c) for c in CHANNELS])
    sigma = np.array([MEASUREMENTS[i].noise_std for i in idx]) * data.track.noise_scale
    return idx, sigma


def signatures(
    data: TrackData, fault: str, seed: int, onset: int | None = None
) -> tuple[np.ndarray, np.ndarray, int]:
    """``(noise-free signature, measured residual, onset)`` of ``fault`` on ``seed``.

    Both arrays are ``(n_samples − onset, 5)`` in units of σ from the onset on. ``onset``
    overrides the track's drawn onset (to align a hypothesis with the true fault's onset).
    """
    idx, sigma = _noise(data)
    spec = data.track.fault_spec(fault, seed)
    if onset is not None:
        spec = spec.replace(onset=int(onset))
    loaded = data.simulate([seed], spec)[0]
    ep = loaded.episode
    if ep.fault_onset is None or ep.y_clean is None:
        raise ValueError(f"{fault} on seed {seed} ended before its onset; pick another seed")
    ref = data.reference(seed)[: ep.n_samples, idx]
    k0 = int(ep.fault_onset)
    clean = (ep.y_clean[k0:, idx] - ref[k0:]) / sigma
    measured = (ep.y[k0:, idx] - ref[k0:]) / sigma
    return clean, measured, k0


def _ss_min(r: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``min_{a>=0} Σ_{k<n} ‖r(k) − a s(k)‖²`` for every n (cumulative least squares)."""
    rr = np.cumsum(np.sum(r * r, axis=1))
    rs = np.cumsum(np.sum(r * s, axis=1))
    ss = np.cumsum(np.sum(s * s, axis=1))
    a = np.where(ss > 0, np.maximum(rs, 0.0) / np.where(ss > 0, ss, 1.0), 0.0)
    return rr - 2 * a * rs + a * a * ss


def _first_hold(stat: np.ndarray, level: float) -> float:
    """First index from which ``stat >= level`` holds to the end; ``nan`` if never."""
    below = np.flatnonzero(stat < level)
    if below.size == 0:
        return 0.0
    k = int(below[-1]) + 1
    return float(k) if k < stat.size else float("nan")


@dataclass(frozen=True)
class Isolability:
    """Result of :func:`isolability` for one track (rows: true fault, columns: hypothesis)."""

    track: str
    faults: tuple[str, ...]
    seeds: tuple[int, ...]
    horizon: int
    alpha: float
    window: int
    #: median samples after onset to separate the row fault from the column hypothesis (nan:
    #: not separated within the horizon on at least half the seeds)
    t_sep: np.ndarray
    #: share of seeds on which the row fault is separated from the column within the horizon
    separated: np.ndarray
    #: angle [degrees] between mean signature directions over the first ``window`` samples
    angle: np.ndarray
    #: mean signature over the first ``window`` samples [σ], rows: faults, columns: CHANNELS
    mean_signature: np.ndarray


def separation_times(
    data: TrackData,
    faults: Sequence[str],
    seeds: Sequence[int],
    *,
    horizon: int = 1000,
    alpha: float = 0.01,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per (true fault, hypothesis, seed): samples after onset to separate (``nan``: not within
    ``horizon``); also the noise-free signatures ``(fault, seed, horizon, 5)``."""
    horizon = check("horizon", horizon, Integer(10, 100_000))
    alpha = check("alpha", alpha, Real(0, 0.5, closed="neither"))
    level = math.log(1.0 / alpha)
    F, S = len(faults), len(seeds)
    t = np.full((F, F, S), np.nan)
    sig = np.zeros((F, S, horizon, len(CHANNELS)))
    for b, seed in enumerate(seeds):
        for i, fi in enumerate(faults):
            clean_i, r, k0 = signatures(data, fi, seed)
            n = min(horizon, r.shape[0])
            sig[i, b, :n] = clean_i[:n]
            ss_i = _ss_min(r[:n], clean_i[:n])
            for j, fj in enumerate(faults):
                if j == i:
                    t[i, j, b] = 0.0
                    continue
                clean_j = signatures(data, fj, seed, onset=k0)[0]
                m = min(n, clean_j.shape[0])  # the hypothesis' plant may end early (envelope)
                glr = (_ss_min(r[:m], clean_j[:m]) - ss_i[:m]) / 2.0
                t[i, j, b] = _first_hold(glr, level)
    return t, sig, np.asarray(seeds)


def direction_angles(mean_signature: np.ndarray) -> np.ndarray:
    """Angles [degrees] between the rows of ``mean_signature`` (faults × channels)."""
    m = np.asarray(mean_signature, dtype=np.float64)
    norm = np.linalg.norm(m, axis=1, keepdims=True)
    u = m / np.where(norm > 0, norm, 1.0)
    return np.degrees(np.arccos(np.clip(u @ u.T, -1.0, 1.0)))


def isolability(
    track: str = "paper",
    *,
    faults: Sequence[str] | None = None,
    n_seeds: int = 10,
    horizon: int = 1000,
    alpha: float = 0.01,
    window: int = 100,
) -> Isolability:
    """The isolability matrix of ``track`` on its *validation* seeds (never test seeds)."""
    if track not in TRACKS:
        raise ValueError(f"Unknown track {track!r}. Available: {sorted(TRACKS)}")
    tr = TRACKS[track]
    data = TrackData(track=tr)
    faults = tuple(faults or tr.faults)
    n_seeds = check("n_seeds", n_seeds, Integer(1, 1000))
    window = check("window", window, Integer(1, horizon))
    seeds = tuple(range(tr.validation_seed_start, tr.validation_seed_start + n_seeds))
    t, sig, _ = separation_times(data, faults, seeds, horizon=horizon, alpha=alpha)
    med = np.full(t.shape[:2], np.nan)
    share = np.mean(~np.isnan(t), axis=2)
    for i in range(len(faults)):
        for j in range(len(faults)):
            if share[i, j] >= 0.5:
                # nan (not separated) ranks above every number: a median over all seeds
                med[i, j] = float(np.median(np.where(np.isnan(t[i, j]), np.inf, t[i, j])))
    mean_sig = sig[:, :, :window].mean(axis=(1, 2))
    return Isolability(
        track=track,
        faults=faults,
        seeds=seeds,
        horizon=horizon,
        alpha=alpha,
        window=window,
        t_sep=med,
        separated=share,
        angle=direction_angles(mean_sig),
        mean_signature=mean_sig,
    )


def isolability_markdown(res: Isolability) -> str:
    """Three Markdown tables: separation times, direction angles, mean signatures."""
    f = res.faults
    head = "| true \\ hypothesis | " + " | ".join(f) + " |\n|---|" + "---|" * len(f) + "\n"
    lines = [
        f"Track `{res.track}`, validation seeds {res.seeds[0]}..{res.seeds[-1]}: samples after "
        f"onset until the GLR separates the true fault (row) from the hypothesis (column) at "
        f"α = {res.alpha:g}, median over seeds (share of seeds separated within {res.horizon} "
        "samples):",
        "",
        head.rstrip("\n"),
    ]
    for i, fi in enumerate(f):
        cells = []
        for j in range(len(f)):
            if i == j:
                cells.append("—")
                continue
            v = res.t_sep[i, j]
            txt = "not within horizon" if math.isnan(v) else f"{v:.0f}"
            cells.append(f"{txt} ({res.separated[i, j]:.0%})")
        lines.append(f"| {fi} | " + " | ".join(cells) + " |")
    lines += [
        "",
        f"Angle [°] between mean signature directions over the first {res.window} samples:",
        "",
        "| | " + " | ".join(f) + " |",
        "|---|" + "---|" * len(f),
    ]
    for i, fi in enumerate(f):
        lines.append(f"| {fi} | " + " | ".join(f"{a:.0f}" for a in res.angle[i]) + " |")
    lines += [
        "",
        f"Mean signature over the first {res.window} samples [σ]:",
        "",
        "| fault | " + " | ".join(CHANNELS) + " |",
        "|---|" + "---|" * len(CHANNELS),
    ]
    for i, fi in enumerate(f):
        lines.append(f"| {fi} | " + " | ".join(f"{v:+.1f}" for v in res.mean_signature[i]) + " |")
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    p = command_parser(
        "evaluation.isolation.isolability",
        (__doc__ or "").split("\n")[0],
        (
            ("--track paper", "the paper track's isolability tables on 10 validation seeds"),
            ("--track all --seeds 4 --horizon 500", "every track, quicker"),
        ),
    )
    p.add_argument("--track", default="paper", help="comma-separated track names (or 'all')")
    p.add_argument("--seeds", type=int, default=10, help="validation seeds per fault")
    p.add_argument("--horizon", type=int, default=1000, help="samples after onset analysed")
    p.add_argument("--alpha", type=float, default=0.01, help="error rate of the GLR threshold")
    p.add_argument("--window", type=int, default=100, help="samples of the mean signature")
    return run_command(p, _tables, argv)


def _tables(a: argparse.Namespace) -> int:
    """The work of :func:`main`: its failures (and a Ctrl-C) are reported by :func:`run_command`."""
    names = sorted(TRACKS) if a.track == "all" else [t.strip() for t in a.track.split(",")]
    for name in names:
        res = isolability(name, n_seeds=a.seeds, horizon=a.horizon, alpha=a.alpha, window=a.window)
        print(isolability_markdown(res))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
