"""Write simulated FCC datasets: ``python -m fcc_env.generate --scenario f1 --seeds 0-9 --out DIR``.

A dataset is one table file (one row per sample, episodes stacked, an ``episode`` column) plus a
JSON sidecar of the same stem. The table is CSV (``--out x.csv``) or Parquet (``--out x.parquet``,
needs the optional ``pyarrow``: ``pip install 'fcc-fault-diagnosis[parquet]'``). The sidecar's
``columns`` maps every column, in file order, to its ``unit``, ``description`` and ``role``; "none"
is always JSON ``null`` (a nominal episode's fault onset and magnitude, an episode that was never
terminated), never ``-1``. A Parquet table repeats each column's record in its schema's field
metadata (``pyarrow.parquet.read_schema(path).field("T_rx").metadata[b"unit"]``,
:func:`fcc_env.dataset_schema.field_metadata`). Column roles are also listed in ``roles``:

* ``measured``: the Table 1 measurements as the sensors report them (noisy);
* ``manipulated``, ``setpoint`` (closed loop only, ``--closed-loop``): what the control system
  records, as ``FCC-closedloop-v0`` observes it: the valve command ``u_F`` (and the air ``R_ar``,
  a measured column) and the set points ``T_rx_sp``, ``T_rg1_sp`` (noise-free);
* ``commanded``: manipulated variables as commanded (``cmd_u_F`` valve, ``cmd_R_ar`` air);
* ``truth``: what only a simulator knows (applied disturbances ``in_*``, noise-free
  measurements ``clean_*``, the fault label ``fault_active``, optionally the states ``x_*``).

Diagnosers and the modelling loop read ``measured`` and ``commanded`` only.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fcc_common.invocation import check_out_path, command_parser, run_command
from fcc_common.io import (
    PARQUET_SUFFIXES,
    atomic_open,
    atomic_write_json,
    read_columns,
    require_pyarrow,
)
from fcc_common.progress import add_progress_flag, auto_progress, progress_bar
from fcc_common.validation import Real, check, invalid
from fcc_env import CLOSED_LOOP_ENV_ID, ENV_ID, MODEL_VERSION
from fcc_env import effects as fx
from fcc_env.closed_loop import CLOSED_LOOP_ROLES, CLOSED_LOOP_UNITS
from fcc_env.dataset_schema import parquet_table
from fcc_env.params import (
    INPUT_NAMES,
    INPUT_UNITS,
    MEASUREMENT_NAMES,
    MEASUREMENTS,
    STATE_NAMES,
    STATE_UNITS,
    FCCParams,
)
from fcc_env.plant import DEFAULT_VALVE_BETA, ENV_PLANT_KEYWORDS, PlantConfig, plant_from_request
from fcc_env.scenarios import (
    DEFAULT_N_SAMPLES,
    ENV_FAULT_KEYWORDS,
    FaultSpec,
    fault_from_request,
    scenario_names,
)
from fcc_env.simulation import (
    DEFAULT_MEMORY_BUDGET_BYTES,
    SEEDS_RANGE,
    BatchResult,
    check_memory,
    simulate_episodes,
)

DATASET_FORMAT = "fcc-dataset"
#: 2: ``columns`` maps each column to its unit, description and role (was a list of names; a
#: dict iterates over the same names in the same order); ``fault_magnitudes`` null, not 0, for an
#: episode without a fault; Parquet tables.
DATASET_FORMAT_VERSION = 2
#: Table file endings :func:`write_dataset` writes.
DATASET_SUFFIXES = (".csv", *PARQUET_SUFFIXES)

_INPUT_DESCRIPTIONS = {
    "u_F": "regenerated-catalyst slide-valve command (flow-equivalent opening)",
    "R_ar": "combustion air flow rate",
    "T_ar": "air temperature",
    "T_fp": "feed temperature",
    "F_feed": "feed rate",
    "f_coke": "feed coking factor",
}
_STATE_DESCRIPTIONS = {
    "W_rx": "reactor/stripper catalyst holdup",
    "C_sc": "coke on spent catalyst",
    "W1": "stage-1 dense-bed holdup",
    "C1": "stage-1 coke on catalyst",
    "T1": "stage-1 dense-bed temperature",
    "W2": "stage-2 dense-bed holdup",
    "C2": "stage-2 coke on catalyst (regenerated catalyst)",
    "T2": "stage-2 dense-bed temperature",
    "W_sp": "regenerated-catalyst well/standpipe inventory",
    "T_d1": "stage-1 dilute-phase temperature",
    "T_dg": "general dilute-phase temperature",
}


def column_metadata(names: Sequence[str]) -> dict[str, dict[str, str]]:
    """``{column: {"unit", "description", "role"}}`` for the columns :func:`write_dataset` writes."""
    meas = {m.name: m for m in MEASUREMENTS}
    inputs = dict(zip(INPUT_NAMES, INPUT_UNITS, strict=True))
    states = dict(zip(STATE_NAMES, STATE_UNITS, strict=True))
    fixed = {
        "episode": ("-", "episode index in this file (0, 1, ...)", "index"),
        "seed": ("-", "simulation seed of the episode", "index"),
        "k": ("-", "sample index within the episode", "index"),
        "time_s": ("s", "time since the episode start", "index"),
        "cmd_u_F": ("kg/s", "commanded " + _INPUT_DESCRIPTIONS["u_F"], "commanded"),
        "cmd_R_ar": ("t/h", "commanded " + _INPUT_DESCRIPTIONS["R_ar"], "commanded"),
        "fault_active": ("-", "1 while the fault is applied, else 0", "truth"),
        # a sensor fault's dropouts (fcc_env.sensor_faults): what the DCS flags beside the value
        "sensor_dropout": ("-", "1 where the faulty channel holds its last good value", "status"),
        # closed loop (FCC-closedloop-v0): what the control system records besides Table 1
        "u_F": (
            CLOSED_LOOP_UNITS["u_F"],
            "regenerated-catalyst slide valve command, as the T_rx controller sets it",
            "manipulated",
        ),
        "T_rx_sp": (CLOSED_LOOP_UNITS["T_rx_sp"], "riser outlet temperature set point", "setpoint"),
        "T_rg1_sp": (
            CLOSED_LOOP_UNITS["T_rg1_sp"],
            "stage-1 regenerator bed temperature set point",
            "setpoint",
        ),
    }
    out: dict[str, dict[str, str]] = {}
    for n in names:
        prefix, _, base = n.partition("_")
        if n in fixed:
            unit, desc, role = fixed[n]
        elif n in meas:
            unit, desc, role = meas[n].unit, f"{meas[n].description} (measured, noisy)", "measured"
        elif prefix == "in" and base in inputs:
            unit, desc, role = (
                inputs[base],
                f"{_INPUT_DESCRIPTIONS[base]} applied to the plant",
                "truth",
            )
        elif prefix == "clean" and base in meas:
            unit, desc, role = meas[base].unit, f"{meas[base].description} (noise-free)", "truth"
        elif prefix == "x" and base in states:
            unit, desc, role = states[base], f"state: {_STATE_DESCRIPTIONS[base]}", "truth"
        else:
            raise ValueError(f"column {n!r} has no metadata; add it to fcc_env.generate")
        out[n] = {"unit": unit, "description": desc, "role": role}
    return out


def parse_seeds(
    text: str,
    *,
    n_samples: int | None = None,
    memory_budget_bytes: float = DEFAULT_MEMORY_BUDGET_BYTES,
) -> list[int]:
    """``"0-4,10"`` → ``[0, 1, 2, 3, 4, 10]``; errors name the bad piece.

    With ``n_samples``, a request whose batch would exceed ``memory_budget_bytes``
    (:func:`fcc_env.simulation.check_memory`) is refused before the seed list is built.
    """
    pieces: list[range] = []
    for part in text.split(","):
        part = part.strip()
        try:
            if "-" in part[1:]:
                lo, hi = part.split("-", 1) if not part.startswith("-") else (part, "")
                a, b = int(lo), int(hi)
                if b < a:
                    raise ValueError
                pieces.append(range(a, b + 1))
            else:
                a = int(part)
                pieces.append(range(a, a + 1))
        except ValueError:
            raise invalid(
                "seeds", text, "integers and ranges like '0-9,20'", f"bad piece {part!r}"
            ) from None
    if n_samples is not None:
        try:
            check_memory(sum(map(len, pieces)), n_samples, memory_budget_bytes)
        except ValueError as e:
            raise ValueError(f"--seeds {text} --samples {n_samples}: {e}") from None
    seeds = [s for r in pieces for s in r]
    return list(check("seeds", seeds, SEEDS_RANGE))


def plant_json(plant: PlantConfig) -> dict[str, Any]:
    """The sidecar record of a plant (the env keyword names; ``params`` only if not declared)."""
    declared = FCCParams().replace(beta_sv=plant.valve_beta)
    ex = plant.excitation
    record = {
        "valve_beta": plant.valve_beta,
        "sample_time_s": plant.sample_time_s,
        "rk4_substeps": plant.rk4_substeps,
        "excitation": False if ex is None else dataclasses.asdict(ex),
        "noise_scale": plant.noise_scale,
        "params": None if plant.params == declared else dataclasses.asdict(plant.params),
    }
    if plant.regulatory is not None:  # only in closed loop: open-loop sidecars stay as they were
        record["regulatory"] = dataclasses.asdict(plant.regulatory)
    return record


def write_dataset(
    path: str | os.PathLike,
    *,
    fault: FaultSpec | None = None,
    plant: PlantConfig | None = None,
    seeds: Sequence[int] = (0,),
    n_samples: int = DEFAULT_N_SAMPLES,
    include_states: bool = False,
    plant_effects: Sequence[Any] = (),
    scenario: str | None = None,
    memory_budget_bytes: float = DEFAULT_MEMORY_BUDGET_BYTES,
    progress: bool | None = False,
    **env_kwargs: Any,
) -> Path:
    """Simulate ``seeds`` and write ``path`` (``.csv``, or ``.parquet``/``.pq`` with ``pyarrow``)
    plus ``path.with_suffix('.json')``.

    ``progress``: bars over the episodes simulated and written, on standard error (``None``:
    when it is a terminal; :mod:`fcc_common.progress`); the files are the same bytes either way.

    ``fault`` and ``plant`` as for :func:`fcc_env.simulate_episodes`, or the env's keywords
    ``scenario`` and ``env_kwargs`` (``fault_time``, ``valve_beta``, ``noise_scale``...);
    the sidecar records the resolved ``fault`` and ``plant``. ``plant_effects`` are undeclared
    effects (:mod:`fcc_env.effects`): recorded under ``truth_plant_effects`` for reproducibility,
    a field the modelling loop never reads. A request whose arrays would exceed
    ``memory_budget_bytes`` (default 4 GiB) is refused before simulating. Both files are written atomically
    (:mod:`fcc_common.io`), so a crash never leaves a torn file, with the permissions of a plain
    ``open`` (0o666 less the umask). Returns the table's path.
    """
    out = Path(path)
    if out.suffix.lower() not in DATASET_SUFFIXES:
        raise invalid("path", str(out), f"a file name ending in one of {list(DATASET_SUFFIXES)}")
    parquet = out.suffix.lower() in PARQUET_SUFFIXES
    pq = require_pyarrow(out, "writing") if parquet else None  # before simulating
    fault_kw = {k: env_kwargs.pop(k) for k in ENV_FAULT_KEYWORDS if k in env_kwargs}
    spec = fault_from_request(fault, {**fault_kw, "scenario": scenario})
    unknown = sorted(set(env_kwargs) - set(ENV_PLANT_KEYWORDS))
    if unknown:
        raise ValueError(
            f"Unknown option(s) {unknown}. Allowed: {[*ENV_FAULT_KEYWORDS, *ENV_PLANT_KEYWORDS]}"
        )
    config = plant_from_request(plant, env_kwargs)
    effects = fx.resolve(plant_effects)
    batch = simulate_in_chunks(
        seeds,
        n_samples,
        progress=progress,
        fault=spec,
        plant=config,
        plant_effects=effects,
        memory_budget_bytes=memory_budget_bytes,
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
    closed = config.regulatory is not None
    for name in batch.channels[len(MEASUREMENT_NAMES) :]:  # closed loop: valve, set points
        cols[name] = batch.observations[:, :, batch.channels.index(name)].astype(np.float64).ravel()
    cols["cmd_u_F"] = batch.inputs[:, :, 0].ravel()
    cols["cmd_R_ar"] = batch.inputs[:, :, 1].ravel()
    for i, name in enumerate(INPUT_NAMES):
        cols[f"in_{name}"] = batch.inputs[:, :, i].ravel()
    for i, name in enumerate(MEASUREMENT_NAMES):
        cols[f"clean_{name}"] = batch.y_clean[:, :, i].ravel()
    cols["fault_active"] = batch.fault_active.astype(np.int8).ravel()
    channel_fault = any(c is not None for c in batch.fault_channels)
    if channel_fault:  # only then: the paper's datasets keep their columns
        cols["sensor_dropout"] = batch.sensor_dropout.astype(np.int8).ravel()
    if include_states:
        for i, name in enumerate(STATE_NAMES):
            cols[f"x_{name}"] = batch.states[:, :, i].ravel()
    names = list(cols)
    meta = {
        "format": DATASET_FORMAT,
        "format_version": DATASET_FORMAT_VERSION,
        "model_version": MODEL_VERSION,
        "env_id": CLOSED_LOOP_ENV_ID if closed else ENV_ID,
        "scenario": spec.scenario,
        "fault": spec.to_json(),
        "plant": plant_json(config),
        "seeds": list(batch.seeds),
        "scenarios": list(batch.scenarios),
        "fault_onsets": list(batch.fault_onsets),
        **({"fault_channels": list(batch.fault_channels)} if channel_fault else {}),
        # None (JSON null) for an episode without a fault, as its onset
        "fault_magnitudes": [
            None if onset is None else float(m)
            for onset, m in zip(batch.fault_onsets, batch.fault_magnitudes, strict=True)
        ],
        # None (JSON null) for an episode that stayed inside the envelope
        "terminated_at": [int(t) if t >= 0 else None for t in batch.terminated_at],
        "n_samples": T,
        "sample_time_s": batch.sample_time_s,
        "truth_plant_effects": [
            e.describe() if hasattr(e, "describe") else {"id": "custom", "repr": repr(e)}
            for e in effects
        ],
        "roles": {
            "index": ["episode", "seed", "k", "time_s"],
            "measured": list(MEASUREMENT_NAMES),
            **(
                {r: list(CLOSED_LOOP_ROLES[r]) for r in ("manipulated", "setpoint")}
                if closed
                else {}
            ),
            "commanded": ["cmd_u_F", "cmd_R_ar"],
            **({"status": ["sensor_dropout"]} if channel_fault else {}),
            "truth": [n for n in names if n.startswith(("in_", "clean_", "x_"))] + ["fault_active"],
        },
        "columns": column_metadata(names),
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    # table first, sidecar last: a sidecar never describes a table that is not there
    if pq is not None:
        # the schema repeats each column's unit, role and description for sidecar-blind readers
        table = parquet_table(cols, meta["columns"])
        with atomic_open(out, "wb") as fh:
            pq.write_table(table, fh)
    else:
        data = np.column_stack([cols[n] for n in names])
        fmt = ["%d", "%d", "%d", "%.1f"] + ["%.10g"] * (len(names) - 4)
        fmt[names.index("fault_active")] = "%d"
        if channel_fault:
            fmt[names.index("sensor_dropout")] = "%d"
        with atomic_open(out, "w") as fh:
            fh.write(",".join(names) + "\n")  # np.savetxt's header line
            bar = progress_bar(
                range(B), desc=f"writing {out.name}", unit="episode", progress=progress
            )
            for b in bar:  # an episode's rows at a time: the same text as all rows at once
                np.savetxt(fh, data[b * T : (b + 1) * T], delimiter=",", fmt=fmt)
    atomic_write_json(out.with_suffix(".json"), meta)
    return out


#: Episodes simulated at a time under a progress bar (the bar moves by as many).
PROGRESS_CHUNK = 16
#: The fields of :class:`~fcc_env.simulation.BatchResult` that hold one entry per episode.
_PER_EPISODE = (
    "seeds",
    "fault_labels",
    "scenarios",
    "fault_onsets",
    "fault_magnitudes",
    "termination_reasons",
    "fault_channels",
)


def simulate_in_chunks(
    seeds: Sequence[int], n_samples: int, *, progress: bool | None, **kwargs: Any
) -> BatchResult:
    """:func:`fcc_env.simulate_episodes` (``kwargs`` as there), with a bar over the episodes
    when ``progress`` asks for one: then :data:`PROGRESS_CHUNK` seeds at a time, joined. An
    episode depends on its seed only, not on the others of its batch, so the result is the same
    (tested); without a bar it is one call."""
    if not auto_progress(progress):
        return simulate_episodes(seeds, n_samples, **kwargs)
    seeds = list(check("seeds", seeds, SEEDS_RANGE))
    budget = kwargs.get("memory_budget_bytes", DEFAULT_MEMORY_BUDGET_BYTES)
    check_memory(len(seeds), n_samples, budget)  # the whole request, before a first chunk
    fault = kwargs.pop("fault", None)  # one for all, or one per seed (then cut as the seeds)
    parts = []
    with progress_bar(total=len(seeds), desc="simulating", unit="episode", progress=True) as bar:
        for i in range(0, len(seeds), PROGRESS_CHUNK):
            cut = slice(i, i + PROGRESS_CHUNK)
            mine = fault[cut] if isinstance(fault, list | tuple) else fault
            parts.append(simulate_episodes(seeds[cut], n_samples, fault=mine, **kwargs))
            bar.update(len(parts[-1].seeds))
    joined: dict[str, Any] = {}
    for f in dataclasses.fields(BatchResult):
        values = [getattr(part, f.name) for part in parts]
        if f.name in _PER_EPISODE:
            joined[f.name] = tuple(v for value in values for v in value)
        elif isinstance(values[0], np.ndarray):
            joined[f.name] = np.concatenate(values)
        else:  # the same in every chunk: channels, names, the sample time
            joined[f.name] = values[0]
    return BatchResult(**joined)


def read_sidecar(path: str | os.PathLike) -> dict[str, Any]:
    """The JSON sidecar of the dataset ``path`` (a table written by :func:`write_dataset`),
    checked: the dataset and its sidecar exist and the sidecar has this library's format tag."""
    csv = Path(path)
    sidecar = csv.with_suffix(".json")
    if not csv.is_file():
        raise ValueError(f"dataset {str(csv)!r} does not exist")
    if not sidecar.is_file():
        raise ValueError(f"dataset {str(csv)!r} has no JSON sidecar {sidecar.name!r}")
    try:
        meta = json.loads(sidecar.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise ValueError(f"sidecar {str(sidecar)!r} is not valid JSON: {e}") from e
    except UnicodeDecodeError as e:
        raise ValueError(
            f"sidecar {str(sidecar)!r} is not UTF-8 text (byte {e.object[e.start : e.start + 1]!r}"
            f" at byte {e.start + 1}); allowed: UTF-8 JSON, so save the file as UTF-8"
        ) from e
    if not isinstance(meta, dict) or meta.get("format") != DATASET_FORMAT:
        got = meta.get("format") if isinstance(meta, dict) else meta
        raise ValueError(
            f"sidecar {str(sidecar)!r} is not an FCC dataset sidecar (needs format "
            f"{DATASET_FORMAT!r}, got {got!r})"
        )
    return meta


def read_dataset(path: str | os.PathLike) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Read a dataset written by :func:`write_dataset` (CSV or Parquet): ``(sidecar, {column:
    array})``."""
    meta = read_sidecar(path)
    names, table = read_columns(path)
    return meta, {n: table[:, j] for j, n in enumerate(names)}


def main(argv: Sequence[str] | None = None) -> int:
    parser = command_parser(
        "fcc_env.generate",
        "Simulate FCC-v0 episodes and write them as CSV or Parquet + JSON sidecar.",
        (
            ("--scenario f1 --seeds 0-9 --out data/f1.csv", "ten episodes of fault f1, as CSV"),
            (
                "--scenario f2 --seeds 0-4 --fault-profile incipient --ramp-samples 500 "
                "--out data/f2.parquet",
                "incipient f2 faults as Parquet (needs pyarrow)",
            ),
            (
                "--closed-loop --seeds 0-3 --states --out data/closed.csv",
                "healthy closed-loop episodes with the valve command, set points and states",
            ),
        ),
    )
    parser.add_argument(
        "--out",
        required=True,
        help="output .csv or .parquet (needs pyarrow) path (sidecar: same stem .json)",
    )
    parser.add_argument(
        "--scenario",
        default="nominal",
        help=f"one of {list(scenario_names(include_path_faults=True))} or 'random'",
    )
    parser.add_argument("--seeds", default="0", help="seeds, e.g. '0-9,20' (default 0)")
    parser.add_argument(
        "--samples",
        type=int,
        default=DEFAULT_N_SAMPLES,
        help=f"samples per episode ({DEFAULT_N_SAMPLES})",
    )
    parser.add_argument("--fault-time", type=int, default=None, help="onset sample")
    parser.add_argument(
        "--fault-magnitude",
        type=float,
        default=None,
        help="size: a relative change (a sensor or actuator fault: its own unit)",
    )
    parser.add_argument("--fault-profile", default=None, help="abrupt (default) or incipient")
    parser.add_argument("--ramp-samples", type=int, default=None, help="incipient ramp length")
    parser.add_argument(
        "--fault-channel", default=None, help="a sensor fault's measured channel (T_rx)"
    )
    parser.add_argument(
        "--valve-beta", type=float, default=None, help=f"0 = flow mode ({DEFAULT_VALVE_BETA})"
    )
    parser.add_argument("--noise-scale", type=float, default=None, help="0 = noise-free (1)")
    parser.add_argument("--no-excitation", action="store_true", help="hold inputs at nominal")
    parser.add_argument("--states", action="store_true", help="also write the 11 states")
    parser.add_argument(
        "--closed-loop",
        action="store_true",
        help="the plant under its regulatory layer (FCC-closedloop-v0): adds the valve command "
        "u_F and the set points T_rx_sp, T_rg1_sp",
    )
    parser.add_argument(
        "--memory-budget-gib",
        type=float,
        default=DEFAULT_MEMORY_BUDGET_BYTES / 2**30,
        metavar="GIB",
        help="refuse requests whose arrays would need more memory "
        f"(default {DEFAULT_MEMORY_BUDGET_BYTES / 2**30:g} GiB)",
    )
    parser.add_argument(
        "--plant-effect",
        action="append",
        default=[],
        metavar="ID[,param=value...]",
        help="undeclared plant effect (repeatable), e.g. heat_loss:stage1,extra_ua_kw_per_k=6; "
        "ids: python -c 'import fcc_env.effects as e; print(list(e.available()))'",
    )
    add_progress_flag(parser)
    return run_command(parser, _generate, argv)


def _generate(args: argparse.Namespace) -> int:
    """The work of :func:`main`: its failures are refused by :func:`run_command`."""
    check_out_path("--out", args.out)
    budget = check("--memory-budget-gib", args.memory_budget_gib, Real(0, closed="neither"))
    budget *= 2**30
    fault = fault_from_request(
        None,
        {
            "scenario": args.scenario,
            "fault_time": args.fault_time,
            "fault_magnitude": args.fault_magnitude,
            "fault_profile": args.fault_profile,
            "ramp_samples": args.ramp_samples,
            "fault_channel": args.fault_channel,
        },
    )
    plant = PlantConfig.build(
        valve_beta=args.valve_beta,
        noise_scale=args.noise_scale,
        excitation=not args.no_excitation,
        regulatory=True if args.closed_loop else None,
    )
    path = write_dataset(
        args.out,
        fault=fault,
        plant=plant,
        seeds=parse_seeds(args.seeds, n_samples=args.samples, memory_budget_bytes=budget),
        n_samples=args.samples,
        memory_budget_bytes=budget,
        include_states=args.states,
        plant_effects=[fx.parse(t) for t in args.plant_effect],
        progress=args.progress,
    )
    print(f"wrote {path} and {path.with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
