"""The modelling loop's hidden-effect cases on closed-loop data (issue 31, item 7).

The same cases, sizes and seeds as ``tests/evaluation/discover/test_discover.py`` (its ``CASES``,
``SLOW_CASES``, the out-of-library stage-2 sine and clean data), simulated on
``FCC-closedloop-v0``'s plant (``simulate_episodes(regulatory=...)``) instead of open loop. The
declared model is fed the recorded valve and air commands (the controllers' outputs), as in
open loop it is fed the program's. Two operating programs:

* ``declared``: set-point steps and the feed and air temperature steps, no feed-quality drift
  (``feed_quality_halfrange_rel=0``): the only thing the declared model lacks is the effect, as
  in the open-loop protocol;
* ``program``: the default closed-loop program, whose feed-quality (coking-factor) drift is an
  unmeasured disturbance the declared model lacks too: what a user of recorded closed-loop
  data faces.

Per case: the first effect named (✓ when it is the hidden one), its estimate against the truth,
and the held-out RMSE of the most affected channel before and after, beside the floor (the
declared model on the same seed without the effect), in both loops.

    PYTHONPATH=. python lab/discover_closed_loop.py [--cases fast|all] [--program declared|program|both]

Result (2026-11-27, this machine, 8.5 min for both programs):

* ``declared`` program: all 13 library cases named first, every estimate within the open-loop
  tests' tolerances (e.g. T_fp bias 3.00 for 3, stage-2 heat loss 0.993 for 1, air split 0.0103
  for 0.01), the held-out RMSE of the most affected channel down to its floor (T_d1 8.30 →
  0.502 °C against 0.502 for the afterburn factor); the out-of-library stage-2 sine named
  nothing and flagged unexplained (T_rg2 0.669 against a floor of 0.307 °C); the two clean
  seeds named nothing. The controllers move the traces into the valve and the air, and the
  declared model, fed the recorded commands, follows them there: closed loop costs the loop
  nothing when the declared model lacks only the effect.
* ``program`` (the default closed-loop program, its feed-quality drift unmeasured): every record,
  clean ones too, is flagged unexplained (correctly: the drift is structure the declared model
  lacks), and only 6 of 13 effects are named first (T_fp bias, dilute heat loss, R_ar bias, both
  afterburn factors, air split; the estimates of the first two are off by 41 % and 10 %). The
  other 7 are misnamed or missed: the drift, not the controllers, is what breaks the loop. A
  candidate for an unmeasured time-varying input (a state estimator, not a parametric effect)
  would be the next step; not built.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

import fcc_env
from evaluation import discover as d
from fcc_env import effects as fx
from fcc_env.regulatory import RegulatoryLayer, SetpointProgram

N = 4000
CASES = [  # (effect, parameter, truth, seed): test_discover.py's CASES then SLOW_CASES
    ("sensor_bias:T_fp,bias=3", "bias", 3.0, 0),
    ("sensor_lag:T_rg1,tau_s=60", "tau_s", 60.0, 0),
    ("heat_loss:dilute_general,extra_ua_kw_per_k=0.3", "extra_ua_kw_per_k", 0.3, 0),
    ("catalyst_deactivation,loss_per_day=0.1", "loss_per_day", 0.1, 0),
]
SLOW_CASES = [
    ("sensor_bias:T_rg2,bias=2", "bias", 2.0, 1),
    ("sensor_drift:T_dg,rate_per_h=0.3", "rate_per_h", 0.3, 1),
    ("sensor_drift:T_fp,rate_per_h=0.3", "rate_per_h", 0.3, 1),
    ("sensor_bias:R_ar,bias=1", "bias", 1.0, 1),
    ("feed_coking_drift,rise_per_day=0.05", "rise_per_day", 0.05, 1),
    ("afterburn:dilute1,factor=1.3", "factor", 1.3, 1),
    ("afterburn:dilute_general,factor=1.3", "factor", 1.3, 1),
    ("air_split,delta_alpha1=0.01", "delta_alpha1", 0.01, 1),
    ("heat_loss:stage2,extra_ua_kw_per_k=1", "extra_ua_kw_per_k", 1.0, 1),
]


class SineOnStage2:
    """Outside the library: a 2-hour sinusoidal heat input on the stage-2 bed (as the test)."""

    def d_state(self, t, x, u, params):
        out = np.zeros_like(x)
        out[..., 7] = 2e-3 * np.sin(2 * np.pi * t / 7200.0)  # °C/s on T2
        return out


def layer(program: str) -> RegulatoryLayer | bool:
    if program == "program":
        return True
    return dataclasses.replace(
        RegulatoryLayer(), program=SetpointProgram(feed_quality_halfrange_rel=0.0)
    )


def run_case(text: str | None, pname: str | None, truth: float | None, seed: int, reg) -> str:
    effects = [] if text is None else [fx.parse(text) if isinstance(text, str) else text]
    t0 = time.perf_counter()
    data = d.from_batch(
        fcc_env.simulate_episodes(
            [seed], N, plant=fcc_env.PlantConfig.build(regulatory=reg), plant_effects=effects
        )
    )
    floor = d.heldout_rmse(
        d.from_batch(
            fcc_env.simulate_episodes([seed], N, plant=fcc_env.PlantConfig.build(regulatory=reg))
        )
    )
    rep = d.discover(data, max_effects=2, plots=False).to_json()
    named = rep["effects"][0]["id"] if rep["effects"] else "none"
    hidden = fx.parse(text).effect_id if isinstance(text, str) else None
    ok = "✓" if named == hidden or (hidden is None and named == "none") else "✗"
    est = rep["effects"][0]["params"].get(pname) if rep["effects"] and pname else None
    gap = {c: rep["rmse_before"][c] - floor[c] for c in floor}
    ch = max(gap, key=gap.get)
    return (
        f"| {text if isinstance(text, str) or text is None else 'stage-2 sine (outside)'} | "
        f"{named} {ok} | {'' if est is None else f'{est:.3g} ({truth:g})'} | {ch} | "
        f"{rep['rmse_before'][ch]:.3f} | {rep['rmse_after'][ch]:.3f} | {floor[ch]:.3f} | "
        f"{rep['unexplained']} | {time.perf_counter() - t0:.0f} s |"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", choices=("fast", "all"), default="all")
    ap.add_argument("--program", choices=("declared", "program", "both"), default="both")
    args = ap.parse_args()
    cases = CASES + (SLOW_CASES if args.cases == "all" else [])
    programs = ("declared", "program") if args.program == "both" else (args.program,)
    for program in programs:
        reg = layer(program)
        print(f"\n### closed loop, program: {program}\n")
        print(
            "| hidden effect | named first | estimate (truth) | channel | RMSE before | "
            "RMSE after | floor | unexplained | time |"
        )
        print("|---|---|---|---|---|---|---|---|---|")
        for text, pname, truth, seed in cases:
            print(run_case(text, pname, truth, seed, reg), flush=True)
        print(run_case(SineOnStage2(), None, None, 1, reg), flush=True)
        for seed in (0, 1):
            print(run_case(None, None, None, seed, reg), flush=True)


if __name__ == "__main__":
    main()
