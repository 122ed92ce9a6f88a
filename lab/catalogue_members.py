"""Record what each member of ``catalogue-isolator`` says on a track's episodes (validation
seeds), so that the composition's settings can be tried on stored outputs in seconds.

The members are fitted as ``catalogue-isolator`` fits them (its own ``fit``: training seeds
only), then each episode's per-member alarm and diagnosis are saved with the truth (the column,
the parts' names and onsets) in one ``.npz`` per episode under ``--out``.

    PYTHONPATH=$PWD python lab/catalogue_members.py --track concurrent --faulty 6 --healthy 4 \
        --seed-start 5000 --out /tmp/catalogue/concurrent
"""

from __future__ import annotations

import argparse
import json
import resource
from pathlib import Path

import numpy as np

import diagnosers
import fcc_env
from diagnosers.loops.air_deficit import air_commands
from evaluation.tracks.catalogue import TRACKS
from evaluation.tracks.track_data import TrackData
from fcc_env.actuator_faults import BLOWER_CAPACITY
from fcc_env.params import INPUT_NAMES
from fcc_env.scenarios import FaultSpec


def cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--track", default="concurrent")
    ap.add_argument("--faulty", type=int, default=6)
    ap.add_argument("--healthy", type=int, default=4)
    ap.add_argument("--train", type=int, default=4)
    ap.add_argument("--train-faults", type=int, default=1)
    ap.add_argument("--seed-start", type=int, default=5000)
    ap.add_argument("--columns", default="")
    ap.add_argument(
        "--alone",
        default="",
        help="a,b: also these faults alone, as the first pair holding them draws them (same "
        "seed, size, onset), saved as column alone:<fault>",
    )
    ap.add_argument("--alone-count", type=int, default=-1, help="episodes each (-1: --faulty)")
    ap.add_argument("--params", default="{}", help="catalogue-isolator hyperparameters (JSON)")
    ap.add_argument("--out", type=Path, default=Path("/tmp/catalogue/concurrent"))
    args = ap.parse_args()
    track = (
        TRACKS[args.track]
        .replace(n_train=args.train, n_train_faults=args.train_faults)
        .with_seeds(test=args.seed_start)
    )
    data = TrackData(track=track)
    c0 = cpu_s()
    train = data.train_episodes() + data.train_fault_episodes()
    iso = diagnosers.make("catalogue-isolator", **json.loads(args.params))
    iso.fit(train)
    print(f"fit on {len(train)} episodes: {cpu_s() - c0:.0f} s CPU", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    columns = args.columns.split(",") if args.columns else list(track.faults)
    cells = [("nominal", s) for s in range(args.seed_start, args.seed_start + args.healthy)]
    cells += [
        (c, s) for c in columns for s in range(args.seed_start, args.seed_start + args.faulty)
    ]
    for fault in filter(None, args.alone.split(",")):
        pair = next(c for c in track.faults if fault in c.split("+"))
        i = pair.split("+").index(fault)
        count = args.faulty if args.alone_count < 0 else args.alone_count
        cells += [(f"alone:{i}:{pair}", s) for s in range(args.seed_start, args.seed_start + count)]
    for column, seed in cells:
        c1 = cpu_s()
        if column == "nominal":
            spec = None
            le = data.simulate([seed], FaultSpec(), test=True)[0]
        elif column.startswith("alone:"):
            _, i, pair = column.split(":")
            spec = track.fault_spec(pair, seed).parts[int(i)]
            column = f"alone:{spec.scenario}"
            le = data.simulate([seed], spec, test=True)[0]
        else:
            spec = track.fault_spec(column, seed)
            le = data.load_test(column, seed)
        ep = le.episode
        outs = iso.member_outputs(ep)
        parts = (spec.parts or (spec,)) if spec is not None else ()
        _, composite, _ = iso.compose(outs)
        binding = _cap_binding(track, spec, parts, seed)
        excess = _cap_excess(ep, parts)
        np.savez(
            args.out / f"{column}_{seed}.npz",
            column=column,
            seed=seed,
            labels=np.array([p.scenario for p in parts], dtype=str),
            onsets=np.array([p.onset for p in parts], dtype=np.int64),
            channels=np.array([str(p.channel) for p in parts], dtype=str),
            n=ep.n_samples,
            member_names=np.array(iso.member_names_, dtype=str),
            claims=np.array(["|".join(m.claims) for m in iso.members_], dtype=str),
            several=np.array([m.several for m in iso.members_], dtype=bool),
            defers=np.array(["|".join(map(str, d)) for d in iso.defers_], dtype=str),
            confirms=np.array([m.confirm or 0 for m in iso.members_], dtype=np.int64),
            alarm=np.stack([o[0] for o in outs]),
            diagnosis=np.stack([o[1] for o in outs]),
            composite=composite,
            cap_binding=binding,
            cap_excess=excess,
        )
        print(
            f"{column} {seed}: {cpu_s() - c1:.0f} s CPU, parts "
            f"{[(p.scenario, p.onset) for p in parts]}, final {composite[-1]!r}"
            + (
                f", cap binds on {binding:.3f} of the samples after its onset, the command "
                f"exceeds it by up to {excess:.2f} t/h"
                if binding >= 0
                else ""
            ),
            flush=True,
        )
    print(f"total {cpu_s() - c0:.0f} s CPU", flush=True)


def _cap_binding(track, spec, parts, seed: int) -> float:
    """The share of the samples after a ``blower-capacity`` part's onset at which the air the
    process receives sits on the cap (the truth's side: what the fault can show at all);
    -1 without such a part."""
    caps = [p for p in parts if p.scenario == "blower-capacity"]
    if not caps:
        return -1.0
    res = fcc_env.simulate_episodes([seed], track.n_samples, fault=spec, plant=track.test_plant)
    end = int(res.terminated_at[0]) if res.terminated_at[0] >= 0 else track.n_samples
    air = res.inputs[0, caps[0].onset : end, INPUT_NAMES.index("R_ar")]
    cap = (1.0 - caps[0].magnitude) * BLOWER_CAPACITY
    return float(np.mean(air >= cap - 1e-9)) if air.size else 0.0


def _cap_excess(ep, parts) -> float:
    """The air loop's command's largest excess over a ``blower-capacity`` part's cap after its
    onset [t/h] (the command computed again from the recorded error, as ``air-deficit`` does;
    ≤ 0: the loop never asked for more than the cap); nan without such a part."""
    caps = [p for p in parts if p.scenario == "blower-capacity"]
    if not caps:
        return float("nan")
    ch = list(ep.channels)
    error = ep.y[:, ch.index("T_rg1_sp")] - ep.y[:, ch.index("T_rg1")]
    command = air_commands(error, ep.sample_time_s)[caps[0].onset :]
    cap = (1.0 - caps[0].magnitude) * BLOWER_CAPACITY
    return float(np.max(command - cap)) if command.size else float("nan")


if __name__ == "__main__":
    main()
