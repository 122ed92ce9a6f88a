"""Write simulated FCC datasets: ``python -m fcc_env.generate --scenario f1 --seeds 0-9 --out DIR``.

A dataset is one CSV file (one row per sample, episodes stacked, an ``episode`` column) plus a JSON
sidecar of the same stem. Column roles are declared in the sidecar:

* ``measured``: the Table 1 measurements as the sensors report them (noisy);
* ``commanded``: manipulated variables as commanded (``cmd_u_F`` valve, ``cmd_R_ar`` air);
* ``truth``: what only a simulator knows (applied disturbances ``in_*``, noise-free
  measurements ``clean_*``, the fault label ``fault_active``, optionally the states ``x_*``).

Diagnosers and the modelling loop read ``measured`` and ``commanded`` only.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fcc_env import effects as fx
from fcc_env.params import INPUT_NAMES, MEASUREMENT_NAMES, STATE_NAMES
from fcc_env.scenarios import SCENARIOS
from fcc_env.simulation import simulate_episodes

DATASET_FORMAT = "fcc-dataset"
DATASET_FORMAT_VERSION = 1


def parse_seeds(text: str) -> list[int]:
    """``"0-4,10"`` → ``[0, 1, 2, 3, 4, 10]``; errors name the bad piece."""
    seeds: list[int] = []
    for part in text.split(","):
        part = part.strip()
        try:
            if "-" in part[1:]:
                lo, hi = part.split("-", 1) if not part.startswith("-") else (part, "")
                a, b = int(lo), int(hi)
                if b < a:
                    raise ValueError
                seeds.extend(range(a, b + 1))
            else:
                seeds.append(int(part))
        except ValueError:
            raise ValueError(
                f"bad seed list piece {part!r} in {text!r}: use integers and ranges like '0-9,20'"
            ) from None
    if any(s < 0 for s in seeds):
        raise ValueError(f"seeds must be non-negative integers, got {text!r}")
    return seeds


def write_dataset(
    path: str | os.PathLike,
    *,
    scenario: str = "nominal",
    seeds: Sequence[int] = (0,),
    n_samples: int = 4000,
    include_states: bool = False,
    plant_effects: Sequence[Any] = (),
    **env_kwargs: Any,
) -> Path:
    """Simulate ``seeds`` and write ``path`` (``.csv``) plus ``path.with_suffix('.json')``.

    ``env_kwargs`` are FCC-v0 options (``fault_time``, ``valve_beta``, ``noise_scale``...);
    ``plant_effects`` undeclared effects (:mod:`fcc_env.effects`): recorded in the sidecar under
    ``truth_plant_effects`` for reproducibility, a field the modelling loop never reads.
    Both files are written to temporaries and renamed, so a crash never leaves a torn dataset.
    Returns the CSV path.
    """
    from fcc_env import MODEL_VERSION

    out = Path(path)
    if out.suffix != ".csv":
        raise ValueError(f"dataset path must end in .csv, got {str(out)!r}")
    effects = fx.resolve(plant_effects)
    batch = simulate_episodes(
        list(seeds), n_samples, scenario=scenario, plant_effects=effects, **env_kwargs
    )
    B, T = batch.observations.shape[:2]
    cols: dict[str, np.ndarray] = {
        "episode": np.repeat(np.arange(B), T),
        "seed": np.repeat(np.array(batch.seeds), T),
        "k": np.tile(np.arange(T), B),
        "time_s": np.tile(np.arange(T) * batch.sample_time_s, B),
    }
    for i, name in enumerate(MEASUREMENT_NAMES):
        cols[name] = batch.observations[:, :, i].astype(np.float64).ravel()
    cols["cmd_u_F"] = batch.inputs[:, :, 0].ravel()
    cols["cmd_R_ar"] = batch.inputs[:, :, 1].ravel()
    for i, name in enumerate(INPUT_NAMES):
        cols[f"in_{name}"] = batch.inputs[:, :, i].ravel()
    for i, name in enumerate(MEASUREMENT_NAMES):
        cols[f"clean_{name}"] = batch.y_clean[:, :, i].ravel()
    cols["fault_active"] = batch.fault_active.astype(np.int8).ravel()
    if include_states:
        for i, name in enumerate(STATE_NAMES):
            cols[f"x_{name}"] = batch.states[:, :, i].ravel()
    names = list(cols)
    meta = {
        "format": DATASET_FORMAT,
        "format_version": DATASET_FORMAT_VERSION,
        "model_version": MODEL_VERSION,
        "env_id": "FCC-v0",
        "scenario": scenario,
        "seeds": list(batch.seeds),
        "scenarios": list(batch.scenarios),
        "fault_onsets": list(batch.fault_onsets),
        "fault_magnitudes": list(batch.fault_magnitudes),
        "terminated_at": batch.terminated_at.tolist(),
        "n_samples": T,
        "sample_time_s": batch.sample_time_s,
        "env_kwargs": {k: v for k, v in env_kwargs.items() if _jsonable(v)},
        "truth_plant_effects": [
            e.describe() if hasattr(e, "describe") else {"id": "custom", "repr": repr(e)}
            for e in effects
        ],
        "roles": {
            "index": ["episode", "seed", "k", "time_s"],
            "measured": list(MEASUREMENT_NAMES),
            "commanded": ["cmd_u_F", "cmd_R_ar"],
            "truth": [n for n in names if n.startswith(("in_", "clean_", "x_"))] + ["fault_active"],
        },
        "columns": names,
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    data = np.column_stack([cols[n] for n in names])
    fmt = ["%d", "%d", "%d", "%.1f"] + ["%.10g"] * (len(names) - 4)
    fmt[names.index("fault_active")] = "%d"
    with tempfile.NamedTemporaryFile("w", dir=out.parent, suffix=".csv.tmp", delete=False) as fh:
        np.savetxt(fh, data, delimiter=",", header=",".join(names), comments="", fmt=fmt)
    sidecar = out.with_suffix(".json")
    with tempfile.NamedTemporaryFile("w", dir=out.parent, suffix=".json.tmp", delete=False) as fj:
        json.dump(meta, fj, indent=2)
    os.replace(fh.name, out)
    os.replace(fj.name, sidecar)
    return out


def _jsonable(v: Any) -> bool:
    try:
        json.dumps(v)
    except TypeError:
        return False
    return True


def read_dataset(path: str | os.PathLike) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Read a dataset written by :func:`write_dataset`: ``(sidecar, {column: array})``."""
    csv = Path(path)
    sidecar = csv.with_suffix(".json")
    if not csv.is_file():
        raise ValueError(f"dataset {str(csv)!r} does not exist")
    if not sidecar.is_file():
        raise ValueError(f"dataset {str(csv)!r} has no JSON sidecar {sidecar.name!r}")
    try:
        meta = json.loads(sidecar.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"{sidecar} is not valid JSON: {e}") from e
    if not isinstance(meta, dict) or meta.get("format") != DATASET_FORMAT:
        raise ValueError(f"{sidecar} is not an FCC dataset sidecar (format {DATASET_FORMAT!r})")
    table = np.genfromtxt(csv, delimiter=",", names=True)
    return meta, {n: np.asarray(table[n]) for n in table.dtype.names}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m fcc_env.generate",
        description="Simulate FCC-v0 episodes and write them as CSV + JSON sidecar.",
    )
    parser.add_argument("--out", required=True, help="output CSV path (sidecar: same stem .json)")
    parser.add_argument(
        "--scenario", default="nominal", help=f"one of {list(SCENARIOS)} or 'random'"
    )
    parser.add_argument("--seeds", default="0", help="seeds, e.g. '0-9,20' (default 0)")
    parser.add_argument("--samples", type=int, default=4000, help="samples per episode (4000)")
    parser.add_argument("--fault-time", type=int, default=None, help="onset sample")
    parser.add_argument("--fault-magnitude", type=float, default=None, help="relative size")
    parser.add_argument("--fault-profile", default="abrupt", help="abrupt or incipient")
    parser.add_argument("--ramp-samples", type=int, default=None, help="incipient ramp length")
    parser.add_argument("--valve-beta", type=float, default=0.3, help="0 = flow mode, 0.3")
    parser.add_argument("--noise-scale", type=float, default=1.0, help="0 = noise-free")
    parser.add_argument("--no-excitation", action="store_true", help="hold inputs at nominal")
    parser.add_argument("--states", action="store_true", help="also write the 11 states")
    parser.add_argument(
        "--plant-effect",
        action="append",
        default=[],
        metavar="ID[,param=value...]",
        help="undeclared plant effect (repeatable), e.g. heat_loss:stage1,extra_ua_kw_per_k=6; "
        "ids: python -c 'import fcc_env.effects as e; print(list(e.available()))'",
    )
    args = parser.parse_args(argv)
    try:
        path = write_dataset(
            args.out,
            scenario=args.scenario,
            seeds=parse_seeds(args.seeds),
            n_samples=args.samples,
            include_states=args.states,
            plant_effects=[fx.parse(t) for t in args.plant_effect],
            fault_time=args.fault_time,
            fault_magnitude=args.fault_magnitude,
            fault_profile=args.fault_profile,
            ramp_samples=args.ramp_samples,
            valve_beta=args.valve_beta,
            noise_scale=args.noise_scale,
            excitation=not args.no_excitation,
        )
    except ValueError as e:
        parser.error(str(e))
    print(f"wrote {path} and {path.with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
