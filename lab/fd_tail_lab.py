"""How the realised false detection rate of ``lrgf-glr`` and its interval depend on the declared
target (and ``on_delay``), on many healthy validation episodes (seeds 5000+; never test seeds),
and what the healthy alarms are. Uses a bank stored by ``lab/baseline_lab.py train`` with its
out-of-fold calibration records, and re-calibrates its alarm stage per target.

It prints the realised r_fd with its 95 % BCa interval over all episodes and over disjoint blocks
of ``--block`` episodes (a track's healthy test episodes: 50 until 2026-11-26, 200 since, so
``--block 200`` shows what a leaderboard on fresh seeds would), the share of episodes with any
alarm and the worst one; with ``--streaks N`` also the run-length profile of the alarms and every
run of N samples or more, with the statistic furthest over its limit and how far each channel was
outside its training range.

    python lab/fd_tail_lab.py --tag=_rg1x10 --targets 0.02,0.03,0.04 --n-healthy 200 \
        --set slow_ewma_lambda=0.02
    python lab/fd_tail_lab.py --tag=_rg1x10 --set slow_ewma_lambda=0.02,on_delay=2 --streaks 10
    python lab/fd_tail_lab.py --tag=_nov --set novelty_gain=0 --by-range

``--by-range`` prints, by where the T_rg1 network's prediction sits in its training range, the
mean normalised remaining error and the alarm samples there (the evidence for ``novelty_gain``).
``--by-plant`` (tracks with plant variation) prints the rank correlation of each episode's alarm
share with its plant draw: the distance to the nearest training plant and to the nominal plant,
each drawn parameter, and the feed-drift period.

    python lab/fd_tail_lab.py --track uncertain --tag=_vf0 --n-healthy 600 --targets 0.04 \
        --set baseline_lambda=0.0001,baseline_hold=1,baseline_filters=[1,10,50],baseline_ridge=3 \
        --by-plant
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from baseline_lab import OUT, at_least, calibration_records, load, parse_set, val_track
from scipy.stats import spearmanr
from tqdm import tqdm

import diagnosers
from evaluation.metrics import episode_scores
from evaluation.metrics.intervals import bootstrap_ci
from evaluation.tracks import TRACKS
from evaluation.tracks.track_data import TrackData
from fcc_env.plant import AFTERBURN_WARNING_C
from fcc_env.uncertainty import GROUP_FIELDS, PlantUncertainty


def healthy_episodes(track: str, n_healthy: int) -> list[np.ndarray]:
    """Measurements ``(T, channels)`` of the track's healthy validation episodes (cached). An
    episode the plant ended early is shorter, so they are a list, not one array."""
    path = OUT / f"healthy-{track}-{n_healthy}.npz"
    legacy = path.with_suffix(".npy")  # cached before episodes could differ in length
    if legacy.exists():
        return list(np.load(legacy))
    if path.exists():
        z = np.load(path)
        return [z[f"y{i}"] for i in range(len(z.files))]
    data = TrackData(track=val_track(track, n_healthy, 1))
    cells = [(sc, seed) for sc, seed in data.cells() if sc == "nominal"]
    ys = [data.load_test(sc, seed).episode.y for sc, seed in tqdm(cells, "simulate")]
    np.savez(path, **{f"y{i}": y for i, y in enumerate(ys)})
    return ys


def alarm_runs(alarm: np.ndarray) -> list[tuple[int, int]]:
    """``(start, length)`` of every run of consecutive alarm samples."""
    edges = np.diff(np.r_[0, alarm.astype(int), 0])
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(int(s), int(e - s)) for s, e in zip(starts, ends, strict=True)]


def streak_report(
    det, ys: list[np.ndarray], detections: list, train: np.ndarray, min_length: int
) -> None:
    """The run-length profile of the healthy alarms and, per run of ``min_length`` samples or
    more, the statistic furthest over its limit, how far each channel was outside its range in
    the training episodes (in training standard deviations, over the run and the 200 samples
    before it) and the share of the run in the afterburn warning region (measured T_d1 − T_rg1
    above ``fcc_env.plant.AFTERBURN_WARNING_C``)."""
    lo, hi, sd = train.min(axis=0), train.max(axis=0), train.std(axis=0)
    names = list(det.channels_)
    d1, rg1 = names.index("T_d1"), names.index("T_rg1")
    lengths, long_runs, warn_all, warn_alarm = [], [], [], []
    for i, (y, d) in enumerate(zip(ys, detections, strict=True)):
        outside = np.maximum((y - hi) / sd, (lo - y) / sd).clip(0.0)
        warning = y[:, d1] - y[:, rg1] > AFTERBURN_WARNING_C
        warn_all.append(warning)
        warn_alarm.append(warning[d.alarm])
        for start, n in alarm_runs(d.alarm):
            lengths.append(n)
            if n >= min_length:
                sl = slice(start, start + n)
                worst = int(np.argmax((d.signal[sl] / d.upper[sl]).max(axis=0)))
                beyond = outside[max(0, start - 200) : start + n].max(axis=0)
                long_runs.append(
                    (i, start, n, det.signal_names_[worst], beyond, warning[sl].mean())
                )
    n_runs = np.array(lengths)
    total = n_runs.sum()
    print(
        f"{len(n_runs)} alarm runs, {total} samples: {np.sum(n_runs == 1)} single samples "
        f"({n_runs[n_runs == 1].sum() / total:.0%} of the alarm samples); "
        f"{np.sum(n_runs >= min_length)} runs of {min_length} or more "
        f"({n_runs[n_runs >= min_length].sum() / total:.0%}); afterburn warning region: "
        f"{np.concatenate(warn_all).mean():.2%} of healthy samples, "
        f"{np.concatenate(warn_alarm).mean():.2%} of alarm samples"
    )
    for i, start, n, stat, beyond, warn in long_runs:
        out = ", ".join(f"{c} {b:.2f}" for c, b in zip(names, beyond, strict=True) if b > 0)
        print(
            f"  episode {i} from sample {start}: {n} samples, {stat}; afterburn warning "
            f"{warn:.0%}; outside training: {out}"
        )


#: bins of where the first exogenous relation's prediction sits in its training range (0 lowest,
#: 1 highest training prediction)
RANGE_BINS = ((-np.inf, 0.0), (0.0, 0.1), (0.1, 0.9), (0.9, 0.95), (0.95, 1.0), (1.0, np.inf))


def range_report(det, ys: list[np.ndarray], detections: list) -> None:
    """Per bin of :data:`RANGE_BINS`: samples, the mean normalised remaining error of every
    relation (before any novelty division) and the alarm samples there."""
    rng = det.prediction_range_
    if rng is None:
        print("no relation with exogenous inputs: no training range to report")
        return
    w = det.steady_window
    pos, err, alarm = [], [], []
    for y, d in zip(ys, detections, strict=True):
        p = det._exogenous_predictions(y)[w:, 0]
        pos.append((p - rng.low[0]) / (rng.high[0] - rng.low[0]))
        err.append(((y[:, det.out_idx_] - det._centre(y)) / det.v_residual_)[w:])
        alarm.append(d.alarm[w:])
    q, e, a = np.concatenate(pos), np.concatenate(err), np.concatenate(alarm)
    names = [det.channels_[i] for i in det.out_idx_]
    print(f"by the {names[det.novelty_relations_[0]]} prediction's place in its training range "
          f"(mean normalised error of {', '.join(names)}; alarm samples):")  # fmt: skip
    for lo, hi in RANGE_BINS:
        m = (q >= lo) & (q < hi) if np.isfinite(hi) else q >= lo
        if m.any():
            print(f"  [{lo}, {hi}): {m.sum()} samples, mean error {np.round(e[m].mean(0), 2)}, "
                  f"{a[m].sum()} of {a.sum()} alarm samples")  # fmt: skip


def plant_draws(track: str, n_healthy: int) -> dict[str, np.ndarray] | None:
    """Per healthy validation episode (in seed order) what its plant draw was: the distance to
    the nearest training plant and to the nominal plant, the feed-drift period and each drawn
    parameter as ``v`` in [−1, 1] (the valve as its gain); None on a track without plant
    variation."""
    if not TRACKS[track].plant_variation:
        return None
    pu = PlantUncertainty()

    def draw(seed: int) -> tuple[np.ndarray, float]:
        truth = pu.draw(seed).truth
        v = [
            ((truth["valve_gain"] if group == "valve" else truth["multipliers"][name]) - 1.0)
            / getattr(pu, group)
            for group, names in GROUP_FIELDS.items()
            for name in names
        ]
        return np.array(v), truth["effects"][0]["params"]["period_s"]

    seeds = val_track(track, n_healthy, 1)
    drawn = [draw(seed) for seed in seeds.test_seeds[:n_healthy]]
    v = np.array([d[0] for d in drawn])
    train = np.array([draw(seed)[0] for seed in seeds.train_seeds])
    return {
        "distance to the nearest training plant": np.linalg.norm(
            v[:, None] - train[None], axis=2
        ).min(axis=1),
        "distance to the nominal plant": np.linalg.norm(v, axis=1),
        "feed-drift period": np.array([d[1] for d in drawn]),
        **{name: v[:, j] for j, name in enumerate(n for ns in GROUP_FIELDS.values() for n in ns)},
    }


def plant_report(draws: dict[str, np.ndarray], r_fd: np.ndarray) -> None:
    """Spearman correlation of the episodes' alarm shares ``r_fd`` with their plant draws
    (:func:`plant_draws`)."""
    print(
        f"Spearman rank correlation of the alarm share with the plant draw ({len(r_fd)} episodes):"
    )
    for name, values in draws.items():
        res = spearmanr(r_fd, values)
        print(f"  {name}: {res.statistic:+.2f} (p {res.pvalue:.2f})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--track", default="paper")
    ap.add_argument("--tag", default="", help="the lab bank's name suffix")
    ap.add_argument("--targets", default="0.03", help="false_alarm_target values, comma-separated")
    ap.add_argument("--n-healthy", type=at_least(1), default=200)
    ap.add_argument(
        "--block",
        type=at_least(2),
        default=50,
        help="episodes per block (50: a track until 2026-11-26; 200 now)",
    )
    ap.add_argument("--set", default="", help="extra hyperparameters k=v,k=v (JSON values)")
    ap.add_argument(
        "--streaks",
        type=at_least(0),
        default=0,
        help="report alarm runs of this many samples or more (0: no report)",
    )
    ap.add_argument(
        "--by-range",
        action="store_true",
        help="report the error and the alarms by where the model's prediction sits in its "
        "training range",
    )
    ap.add_argument(
        "--by-plant",
        action="store_true",
        help="report how each episode's alarm share correlates with its plant draw",
    )
    a = ap.parse_args()
    if a.block > a.n_healthy:
        ap.error(f"--block {a.block}; allowed: at most --n-healthy ({a.n_healthy})")
    try:
        extra = parse_set(a.set)
    except ValueError as err:
        ap.error(str(err))
    det, cal, w, novelty = load(a.track, a.tag)
    ys = healthy_episodes(a.track, a.n_healthy)
    cal_ys = calibration_records(a.track, cal)
    train = None
    if a.streaks:  # the same training episodes, loaded once when the counts match
        train_ys = cal_ys or [
            e.y for e in TrackData(track=val_track(a.track, 1, 1)).train_episodes()
        ]
        train = np.concatenate(train_ys)
    draws = None
    if a.by_plant:  # the same draws for every target
        draws = plant_draws(a.track, len(ys))
        if draws is None:
            print(f"track {a.track!r} draws no plants: no plant report")
    out = []
    for target in [float(t) for t in a.targets.split(",")]:
        det.set_params(false_alarm_target=target, **extra)
        det._calibrate(cal, w, novelty, cal_ys)
        det._fitted_ = True  # the lab re-calibrates the stored bank in place
        detections = [
            det.detect(diagnosers.Episode(y, det.channels_, 10.0))
            for y in tqdm(ys, f"target {target}", leave=False)
        ]
        r_fd = np.array([episode_scores(d.alarm, None)["r_fd"] for d in detections])
        ci = bootstrap_ci(r_fd, method="BCa", rng=0)
        blocks = [r_fd[i : i + a.block] for i in range(0, len(r_fd) - a.block + 1, a.block)]
        block_ci = [bootstrap_ci(b, method="BCa", rng=0) for b in blocks]
        print(
            f"target {target}: r_fd {ci.estimate:.4f} [{ci.low:.4f}, {ci.high:.4f}] over "
            f"{len(r_fd)} episodes; any alarm {np.mean(r_fd > 0):.2f}; worst {r_fd.max():.3f}; "
            f"blocks of {a.block}: "
            + ", ".join(f"{b.estimate:.4f} [{b.low:.4f}, {b.high:.4f}]" for b in block_ci),
            flush=True,
        )
        out.append({"target": target, **extra, "r_fd": r_fd.tolist()})
        if a.streaks:
            streak_report(det, ys, detections, train, a.streaks)
        if a.by_range:
            range_report(det, ys, detections)
        if draws is not None:
            plant_report(draws, r_fd)
    (OUT / f"false-alarm-{a.track}{a.tag}-{int(time.time())}.json").write_text(json.dumps(out))


if __name__ == "__main__":
    main()
