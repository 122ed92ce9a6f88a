"""The closed-loop evidence of the docs (issue 31): stability, responses, faults under control.

``python -m fcc_env.closed_loop_report --out DIR [--terminations N]`` writes to ``DIR``:
``stability.md`` (:func:`fcc_env.closed_loop_analysis.stability_table`: nominal, each fault at its
largest size, the 16 ``uncertain`` corners); ``responses.png`` (noise-free responses to set-point
and disturbance steps); ``fault_signatures.md``/``.csv`` (every registered fault,
:func:`report_faults`, at its default size, faulty − healthy on the same seeds, open and closed loop, as the specification's §7.6 table, with what the
controllers mask and where the signature goes); ``closed_minus_open.png`` (those differences over
time); with ``--terminations N``, ``terminations.json`` (N excited healthy episodes, open against
closed loop). Library functions compute and return; only :func:`main` prints.
``docs/gen_pages.py`` calls :func:`build_report` at every docs build.
"""

from __future__ import annotations

import argparse
import json
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from fcc_common.invocation import check_out_path, command_parser, out_path, run_command
from fcc_common.io import atomic_write, atomic_write_json
from fcc_common.validation import Integer, IntegerSequence, check, check_params, invalid
from fcc_env import CLOSED_LOOP_ENV_ID
from fcc_env.closed_loop import CHANNEL_UNITS, visibility_threshold
from fcc_env.closed_loop_analysis import stability_cases, stability_table
from fcc_env.closed_loop_figures import closed_minus_open_figure, responses_figure
from fcc_env.env import SETPOINT_ACTION_SCALE
from fcc_env.params import INPUT_NAMES
from fcc_env.plant import PlantConfig
from fcc_env.scenarios import FaultSpec, fault_names
from fcc_env.simulation import BatchResult, check_memory, simulate_episodes

__all__ = [
    "SIGNATURE_CHANNELS",
    "FaultDeltas",
    "Report",
    "ReportConfig",
    "Signature",
    "build_report",
    "count_terminations",
    "fault_deltas",
    "masking_table",
    "report_faults",
    "signature_rows",
    "signatures_csv",
    "signatures_note",
    "signatures_table",
    "step_responses",
    "trace_signature",
    "write_report",
]

LOOPS: tuple[str, ...] = ("open", "closed")
#: The channels whose signature is reported: the temperatures that move, the air, the valve.
SIGNATURE_CHANNELS: tuple[str, ...] = ("T_rx", "T_rg1", "T_rg2", "T_d1", "T_dg", "R_ar", "u_F")
_TEMPERATURES = ("T_rx", "T_rg1", "T_rg2", "T_d1", "T_dg")
#: Samples averaged for the "final" difference (the spec's §7.6).
FINAL_WINDOW = 200
_RESPONSE_STEP_AT = 60  # samples (10 min) of steady state before each step


_CONFIG_RANGES = {
    "horizon": Integer(4),
    "seeds": IntegerSequence(0, unique=True, why="one healthy/faulty pair per seed"),
    "response_samples": Integer(_RESPONSE_STEP_AT + 2),
}


@dataclass(frozen=True)
class ReportConfig:
    """The report's sizes: the fault-signature episodes and the response window (samples)."""

    horizon: int = 4000
    onset: int | None = None  # default: half the horizon (the spec's §7.6 uses 2000 of 4000)
    seeds: tuple[int, ...] = (5000, 5001, 5002, 5003)  # validation seeds
    response_samples: int = 1500

    def __post_init__(self) -> None:
        names = ("horizon", "seeds", "response_samples")
        v = check_params({n: getattr(self, n) for n in names}, _CONFIG_RANGES)
        onset = v["horizon"] // 2 if self.onset is None else self.onset
        if not 1 <= onset < v["horizon"] - 1:
            raise invalid("onset", onset, f"an integer in [1, {v['horizon'] - 2}] (horizon - 2)")
        object.__setattr__(self, "seeds", tuple(v["seeds"]))
        object.__setattr__(self, "onset", onset)


@dataclass(frozen=True)
class Signature:
    """A difference trace after onset: largest |Δ| (signed) and its sample after onset, the mean
    of the last samples, the first sample after onset beyond the threshold (None: never)."""

    peak: float
    peak_at: int
    final: float
    t3sigma: int | None


def trace_signature(
    delta: np.ndarray, onset: int, threshold: float, final_window: int = FINAL_WINDOW
) -> Signature:
    """The :class:`Signature` of ``delta`` (T,), samples counted from ``onset`` (0 = onset)."""
    after = np.asarray(delta, dtype=np.float64)[onset:]
    if after.size == 0:
        raise invalid("onset", onset, f"an index below the trace length {np.shape(delta)[0]}")
    i = int(np.argmax(np.abs(after)))
    beyond = np.flatnonzero(np.abs(after) > threshold)
    return Signature(
        peak=float(after[i]),
        peak_at=i,
        final=float(after[-min(final_window, after.size) :].mean()),
        t3sigma=int(beyond[0]) if beyond.size else None,
    )


@dataclass(frozen=True)
class FaultDeltas:
    """Faulty − healthy noise-free differences of one fault in one loop mode.

    ``deltas[channel]`` is (episodes, T); pairs where either episode left the envelope are
    dropped (``dropped`` counts them: later samples mean nothing).
    """

    fault: str
    loop: str
    onset: int
    sample_time_s: float
    deltas: dict[str, np.ndarray]
    dropped: int = 0

    def mean(self, channel: str) -> np.ndarray:
        return self.deltas[channel].mean(axis=0)


def _channel(b: BatchResult, name: str) -> np.ndarray:
    if name in b.channels:
        return b.y_clean[..., b.channels.index(name)]
    return b.inputs[..., INPUT_NAMES.index(name)]  # open loop: u_F is the program's command


def report_faults() -> tuple[str, ...]:
    """The faults the report simulates: every registered one (:func:`fcc_env.fault_names`),
    read when the report is built."""
    return fault_names()


def fault_deltas(fault: str, loop: str, config: ReportConfig) -> FaultDeltas:
    """Simulate healthy and faulty episodes of the same seeds (same program and noise draws;
    the controllers read noisy transmitters, as in the env) and keep the differences."""
    if loop not in LOOPS:
        raise invalid("loop", loop, f"one of {list(LOOPS)}")
    regulatory = True if loop == "closed" else None
    healthy = simulate_episodes(
        list(config.seeds), config.horizon, plant=PlantConfig.build(regulatory=regulatory)
    )
    fault_spec = FaultSpec(scenario=fault, onset=config.onset)
    faulty = simulate_episodes(
        list(config.seeds),
        config.horizon,
        plant=PlantConfig.build(regulatory=regulatory),
        fault=fault_spec,
    )
    ok = (healthy.terminated_at < 0) & (faulty.terminated_at < 0)
    if not ok.any():
        raise RuntimeError(f"every {loop}-loop {fault} pair left the envelope: no signature")
    deltas = {c: (_channel(faulty, c) - _channel(healthy, c))[ok] for c in SIGNATURE_CHANNELS}
    return FaultDeltas(fault, loop, config.onset, healthy.sample_time_s, deltas, int((~ok).sum()))


@dataclass(frozen=True)
class SignatureRow:
    fault: str
    loop: str
    channel: str
    signature: Signature  # of the mean difference over the kept episodes
    final_sd: float  # spread of the final difference across episodes
    threshold: float
    episodes: int


def signature_rows(runs: list[FaultDeltas]) -> list[SignatureRow]:
    """One row per run and channel: the signature of the episode-mean difference."""
    rows = []
    for r in runs:
        for c in SIGNATURE_CHANNELS:
            thr = visibility_threshold(c)
            d = r.deltas[c]
            finals = d[:, -min(FINAL_WINDOW, d.shape[1] - r.onset) :].mean(axis=1)
            rows.append(
                SignatureRow(
                    r.fault,
                    r.loop,
                    c,
                    trace_signature(r.mean(c), r.onset, thr),
                    float(finals.std()),
                    thr,
                    d.shape[0],
                )
            )
    return rows


def _num(x: float, digits: int = 2) -> str:
    return f"{x:+.{digits}f}".replace("-", "−")


def signatures_table(rows: list[SignatureRow]) -> str:
    """Markdown: per fault and channel, open and closed loop side by side (the spec's §7.6)."""
    by = {(r.fault, r.loop, r.channel): r for r in rows}
    lines = [
        "| fault | channel | 3σ | open: peak @ sample | open: final | open: t3σ "
        "| closed: peak @ sample | closed: final | closed: t3σ |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for f in dict.fromkeys(r.fault for r in rows):
        for c in SIGNATURE_CHANNELS:
            cells = [f, f"{c} [{CHANNEL_UNITS[c]}]", f"{by[(f, 'open', c)].threshold:.2f}"]
            for loop in LOOPS:
                r = by[(f, loop, c)]
                s = r.signature
                cells += [
                    f"{_num(s.peak)} @ {s.peak_at}",
                    _num(s.final),
                    "never" if s.t3sigma is None else str(s.t3sigma),
                ]
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def signatures_csv(rows: list[SignatureRow]) -> str:
    """CSV of :func:`signature_rows` (t3sigma empty: never beyond the threshold)."""
    out = [
        "fault,loop,channel,unit,peak,peak_sample,final,final_sd,t3sigma_sample,threshold,episodes"
    ]
    for r in rows:
        s = r.signature
        t3 = "" if s.t3sigma is None else str(s.t3sigma)
        out.append(
            f"{r.fault},{r.loop},{r.channel},{CHANNEL_UNITS[r.channel]},{s.peak:.6g},{s.peak_at},"
            f"{s.final:.6g},{r.final_sd:.4g},{t3},{r.threshold:.4g},{r.episodes}"
        )
    return "\n".join(out) + "\n"


def masking_table(rows: list[SignatureRow]) -> str:
    """Markdown: per fault, closed/open ratio of the final |Δ| on T_rx and T_rg1, the
    temperatures masked (final |Δ| beyond 3σ open loop, within it closed loop), and the
    closed-loop channels that carry the signature (final |Δ| beyond 3σ), largest first."""
    by = {(r.fault, r.loop, r.channel): r for r in rows}
    lines = [
        "| fault | T_rx closed/open | T_rg1 closed/open | masked | closed loop: the signature is in "
        "| valve u_F | air R_ar |",
        "|---|---|---|---|---|---|---|",
    ]
    for f in dict.fromkeys(r.fault for r in rows):
        op = {c: by[(f, "open", c)].signature.final for c in SIGNATURE_CHANNELS}
        cl = {c: by[(f, "closed", c)].signature.final for c in SIGNATURE_CHANNELS}
        seen = {c: abs(cl[c]) / visibility_threshold(c) for c in SIGNATURE_CHANNELS}
        ratios = [abs(cl[c]) / max(abs(op[c]), 1e-12) for c in ("T_rx", "T_rg1")]
        masked = [c for c in _TEMPERATURES if abs(op[c]) > visibility_threshold(c) and seen[c] <= 1]
        carriers = sorted((c for c in SIGNATURE_CHANNELS if seen[c] > 1), key=lambda c: -seen[c])
        carried = ", ".join(f"{c} {_num(cl[c], 1)} {CHANNEL_UNITS[c]}" for c in carriers)
        act = [
            f"{_num(cl[c])} {CHANNEL_UNITS[c]}" + ("" if seen[c] > 1 else " (within 3σ)")
            for c in ("u_F", "R_ar")
        ]
        lines.append(
            f"| {f} | {ratios[0]:.3f} | {ratios[1]:.3f} | {', '.join(masked) or 'none'} | "
            f"{carried or 'nothing beyond 3σ'} | {act[0]} | {act[1]} |"
        )
    return "\n".join(lines)


class InputStep:
    """A plant effect: ``delta`` added to input ``name`` from ``at_s`` seconds on."""

    def __init__(self, name: str, delta: float, at_s: float) -> None:
        self.column, self.delta, self.at_s = INPUT_NAMES.index(name), float(delta), float(at_s)

    def transform_inputs(self, t_s: Any, u: np.ndarray) -> np.ndarray:
        u = np.array(u, dtype=np.float64, copy=True)
        u[..., self.column] += self.delta * (np.asarray(t_s) >= self.at_s)
        return u


@dataclass(frozen=True)
class Response:
    """One closed-loop response: the noise-free observation (T, 11) over time (h)."""

    title: str
    time_h: np.ndarray
    y: np.ndarray  # channels CLOSED_LOOP_CHANNELS
    step_at_h: float


#: The four responses: title, set-point move (°C on T_rx_sp, T_rg1_sp), input step or None.
RESPONSE_CASES: tuple[tuple[str, tuple[float, float], tuple[str, float] | None], ...] = (
    ("T_rx set point +5 °C", (5.0, 0.0), None),
    ("T_rg1 set point +5 °C", (0.0, 5.0), None),
    ("feed temperature T_fp +10 °C", (0.0, 0.0), ("T_fp", 10.0)),
    ("feed coking factor f_coke +3 %", (0.0, 0.0), ("f_coke", 0.03)),
)


def step_responses(config: ReportConfig) -> list[Response]:
    """Noise-free, unexcited closed-loop responses of ``FCC-closedloop-v0`` from the nominal
    steady state, set points held (no program); each step after :data:`_RESPONSE_STEP_AT`."""
    n, k0 = config.response_samples, _RESPONSE_STEP_AT
    ts = PlantConfig().sample_time_s
    out = []
    for title, move, step in RESPONSE_CASES:
        effects = [] if step is None else [InputStep(step[0], step[1], k0 * ts)]
        env = gym.make(
            CLOSED_LOOP_ENV_ID,
            excitation=False,
            noise_scale=0.0,
            sample_time_s=ts,
            regulatory={"program": None},
            max_episode_steps=n,
            plant_effects=effects,
        )
        _, info = env.reset(seed=0)
        ys = [info["y_clean"]]
        action = np.asarray(move) / SETPOINT_ACTION_SCALE
        for k in range(n - 1):
            _, _, term, _, info = env.step(action if k >= k0 else np.zeros(2))
            ys.append(info["y_clean"])
            if term:
                raise RuntimeError(f"the {title} response left the envelope at sample {k + 1}")
        env.close()
        out.append(Response(title, np.arange(n) * ts / 3600.0, np.array(ys), k0 * ts / 3600.0))
    return out


def count_terminations(
    n: int, *, first_seed: int = 5000, horizon: int = 4000, chunk: int = 50
) -> dict[str, Any]:
    """Excited healthy episodes (seeds ``first_seed`` …) that leave the envelope, open against
    closed loop, simulated ``chunk`` seeds at a time to bound memory."""
    check_params({"n": n, "chunk": chunk}, {"n": Integer(1), "chunk": Integer(1)})
    t0 = time.perf_counter()
    counts: dict[str, Any] = {}
    for loop in LOOPS:
        reasons: Counter[str] = Counter()
        for start in range(first_seed, first_seed + n, chunk):
            seeds = list(range(start, min(start + chunk, first_seed + n)))
            b = simulate_episodes(
                seeds,
                horizon,
                plant=PlantConfig.build(regulatory=True if loop == "closed" else None),
            )
            reasons.update(r for r in b.termination_reasons if r is not None)
        counts[loop] = {"terminations": sum(reasons.values()), "reasons": dict(reasons)}
    return {
        "episodes": n,
        "seeds": [first_seed, first_seed + n - 1],
        "horizon": horizon,
        **{f"{loop}_loop": counts[loop] for loop in LOOPS},
        "seconds": round(time.perf_counter() - t0, 1),
    }


@dataclass(frozen=True)
class Report:
    """Everything the report writes, as text and PNG bytes."""

    stability_md: str
    all_stable: bool
    signatures_md: str
    masking_md: str
    signatures_csv: str
    responses_png: bytes
    closed_minus_open_png: bytes
    terminations: dict[str, Any] | None = None


def build_report(config: ReportConfig | None = None, terminations: int = 0) -> Report:
    """Compute every table and figure of the report (``terminations`` 0: skip that count)."""
    config = config or ReportConfig()
    cases = stability_cases()
    runs = [fault_deltas(f, loop, config) for f in report_faults() for loop in LOOPS]
    rows = signature_rows(runs)
    return Report(
        stability_md=stability_table(cases),
        all_stable=all(c.stable for c in cases),
        signatures_md=signatures_table(rows),
        masking_md=masking_table(rows),
        signatures_csv=signatures_csv(rows),
        responses_png=responses_figure(step_responses(config)),
        closed_minus_open_png=closed_minus_open_figure(runs),
        terminations=count_terminations(terminations) if terminations else None,
    )


def signatures_note(config: ReportConfig) -> str:
    """What the fault-signature tables show, with the configuration they were computed on."""
    seeds = ", ".join(map(str, config.seeds))
    return (
        f"Faulty − healthy, noise-free; abrupt faults at the paper's sizes from sample "
        f"{config.onset} of {config.horizon}, the same seeds, program and noise draws for both; "
        f"the mean over seeds {seeds}. Peak and t3σ in samples after onset; final = mean of the "
        f"last {FINAL_WINDOW} samples; 3σ = 3 × the channel's noise std (u_F, noise-free: "
        "3 × 0.5 % of nominal, the air meter's relative resolution)."
    )


def write_report(out: Path, report: Report, config: ReportConfig) -> list[Path]:
    """Write the report's files into ``out`` (each atomically); returns their paths."""
    signatures = f"{signatures_note(config)}\n\n{report.signatures_md}\n\n{report.masking_md}\n"
    files: dict[str, str | bytes] = {
        "stability.md": report.stability_md + "\n",
        "fault_signatures.md": signatures,
        "fault_signatures.csv": report.signatures_csv,
        "responses.png": report.responses_png,
        "closed_minus_open.png": report.closed_minus_open_png,
    }
    paths = [atomic_write(out / name, data) for name, data in files.items()]
    if report.terminations is not None:
        paths.append(atomic_write_json(out / "terminations.json", report.terminations))
    return paths


def main(argv: list[str] | None = None) -> int:
    ap = command_parser(
        "fcc_env.closed_loop_report",
        "Closed-loop evidence: stability, responses, fault signatures, terminations.",
        (
            ("--out results/closed_loop", "the stability table, responses and fault signatures"),
            (
                "--out results/closed_loop --terminations 20",
                "also count terminations of 20 excited healthy episodes, open against closed loop",
            ),
            (
                "--out results/short --horizon 2000 --seeds 5000 5001",
                "shorter fault signatures on two seeds",
            ),
        ),
    )
    ap.add_argument("--out", type=out_path, required=True, help="directory to write into")
    ap.add_argument("--terminations", type=int, default=0, help="healthy episodes to count (0)")
    ap.add_argument("--horizon", type=int, default=4000, help="fault-signature samples (4000)")
    ap.add_argument("--onset", type=int, default=None, help="fault onset (half the horizon)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[5000, 5001, 5002, 5003])
    ap.add_argument("--response-samples", type=int, default=1500, help="response length (1500)")
    return run_command(ap, _report, argv)


#: Most healthy episodes ``--terminations`` simulates (50 at a time, so memory is not the bound).
MAX_TERMINATION_EPISODES = 10_000


def _report(args: argparse.Namespace) -> int:
    """The work of :func:`main`: its failures (and a Ctrl-C) are reported by :func:`run_command`."""
    config = ReportConfig(
        horizon=args.horizon,
        onset=args.onset,
        seeds=tuple(args.seeds),
        response_samples=args.response_samples,
    )
    why = "0 skips the count; 10000 episodes give a termination rate to within 0.2 %"
    check("--terminations", args.terminations, Integer(0, MAX_TERMINATION_EPISODES, why=why))
    # before any work: a healthy and a faulty episode per seed, one response per case
    for flags, n, samples in (
        (
            f"--seeds ({len(config.seeds)}) x --horizon {config.horizon}",
            2 * len(config.seeds),
            config.horizon,
        ),
        (
            f"--response-samples {config.response_samples}",
            len(RESPONSE_CASES),
            config.response_samples,
        ),
    ):
        try:
            check_memory(n, samples)
        except ValueError as e:
            raise ValueError(f"{flags}: {e}") from None
    check_out_path("--out", args.out)
    report = build_report(config, args.terminations)
    paths = write_report(args.out, report, config)
    print(f"stability: {'all stable' if report.all_stable else 'NOT all stable'}")
    print(report.masking_md)
    if report.terminations is not None:
        print("terminations:", json.dumps(report.terminations))
    print("wrote", ", ".join(str(p) for p in paths))
    return 0 if report.all_stable else 1


if __name__ == "__main__":
    raise SystemExit(main())
