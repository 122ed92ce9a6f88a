"""How much of the physical limit comes from knowing the true inputs? Validation seeds only.

Scores the two reference rows of :mod:`evaluation.tracks.oracle` on a track's *validation* protocol
(episodes from seed 5000, calibration from seed 9000): the physical limit (the healthy plant for
the true inputs) and the perfect model driven by the measured inputs (what any
simulation-residual detector reads). ``--channels`` restricts both observers to some
temperatures (e.g. ``T_rg1``: a perfect model of the T_rg1 relation alone). ``--stages
t2,directional`` adds the same two references evaluated by ``lrgf-glr``'s alarm stage
(``OracleConfig(stage="directional")``, declared target ``--target``, default
:data:`evaluation.tracks.oracle.REFERENCE_TARGET`).

    python lab/input_noise_limit.py --track paper --n-healthy 30 --n-faulty 10
    python lab/input_noise_limit.py --track small --n-healthy 60 --stages directional

Prints per fault r_td and mean t_dt [samples] of both rows, and their healthy residual std [°C].
"""

from __future__ import annotations

import argparse

from baseline_lab import at_least

from evaluation.sweep.records import summarize
from evaluation.tracks import TRACKS
from evaluation.tracks.oracle import TRUE_INPUT_STAGES, OracleConfig, OracleStage, oracle_records
from evaluation.tracks.track_data import TrackData
from fcc_env.params import MEASUREMENT_NAMES


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--track", default="paper")
    ap.add_argument("--n-healthy", type=at_least(1), default=30)
    ap.add_argument("--n-faulty", type=at_least(1), default=10)
    ap.add_argument("--channels", default="T_rx,T_rg1,T_rg2,T_d1,T_dg")
    ap.add_argument("--stages", default="t2", help="t2, directional or both, comma-separated")
    ap.add_argument("--target", type=float, default=None, help="the directional stage's target")
    a = ap.parse_args()
    if a.target is not None and not 0.0 < a.target < 0.5:
        ap.error(f"--target {a.target!r}; allowed: a false-alarm share in (0, 0.5)")
    stages = a.stages.split(",")
    # the stages that also read measured inputs (the optimal-detector stages do not)
    allowed = [st.value for st in OracleStage if st not in TRUE_INPUT_STAGES]
    bad = [s for s in stages if s not in allowed]
    if bad:
        ap.error(f"--stages {bad[0]!r}; allowed: {allowed}")
    track = (
        TRACKS[a.track]
        .with_seeds(test=5000, validation=9000)
        .replace(n_healthy=a.n_healthy, n_faulty=a.n_faulty)
    )
    data = TrackData(track=track)
    channels = tuple(a.channels.split(","))
    print(f"track {a.track} (validation seeds), channels {', '.join(channels)}")
    for stage, inputs in ((st, i) for st in stages for i in ("true", "measured")):
        target = a.target if stage == OracleStage.DIRECTIONAL else None
        cfg = OracleConfig(channels=channels, inputs=inputs, stage=stage, target=target)
        seed = track.validation_seeds[0]
        y = data.load_test("nominal", seed).episode.y
        ref = data.reference(seed, y if inputs == "measured" else None)[: len(y)]
        idx = [MEASUREMENT_NAMES.index(c) for c in channels]
        std = (y[:, idx] - ref[:, idx]).std(axis=0)
        stats = {s.scenario: s for s in summarize(oracle_records(data, cfg))}
        line = f"{cfg.label:50s} r_fd {stats['nominal'].r_fd:.4f}"
        for f in ("f1", "f2", "f3", "f4"):
            if f in stats:
                line += f" | {f} {stats[f].r_td:.3f}/{stats[f].t_dt:.0f}"
        print(line)
        print(f"{'':50s} healthy residual std [°C]: " + ", ".join(
            f"{c} {v:.3f}" for c, v in zip(channels, std, strict=True)))  # fmt: skip


if __name__ == "__main__":
    main()
