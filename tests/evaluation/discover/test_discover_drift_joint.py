"""The drift estimate's level and trend fitted with every candidate (issue 42, the joint fit of
``evaluation.discover.drift_joint``; the full table: lab/discover_drift.py, lab/discover_drift.md).
"""

from __future__ import annotations

import numpy as np
import pytest

import fcc_env
from evaluation import discover as d
from evaluation.discover.drift_joint import (
    DRIFT_LINE_ID,
    DriftLine,
    changes_coking,
    check_fit,
    drift_line_candidate,
)
from evaluation.discover.fitting import fit_effects
from evaluation.discover.selection import Accepted, assign, findings, nuisance_mask, stacked
from fcc_env import effects as fx

F_COKE = fcc_env.INPUT_NAMES.index("f_coke")


def test_the_line_adds_level_and_trend_to_the_coking_factor_only() -> None:
    t = np.array([0.0, 43_200.0, 86_400.0])  # 0, 12 h, 24 h
    u = np.ones((2, 3, 6))
    out = DriftLine(level=0.01, trend_per_day=0.1, centre_s=43_200.0).transform_inputs(t, u)
    np.testing.assert_allclose(out[..., F_COKE], [[0.96, 1.01, 1.06]] * 2)
    others = [i for i in range(6) if i != F_COKE]
    np.testing.assert_array_equal(out[..., others], u[..., others])
    assert u[0, 0, F_COKE] == 1.0  # the input is not changed in place
    np.testing.assert_array_equal(DriftLine(0.0, 0.0, 0.0).transform_inputs(t, u), u)


def test_the_line_candidate_and_its_settings() -> None:
    cand = drift_line_candidate(20_000.0)
    assert cand.id == DRIFT_LINE_ID
    assert [p.name for p in cand.params] == ["level", "trend_per_day"]
    assert all(p.null == 0.0 and p.low < 0.0 < p.high for p in cand.params)
    assert cand.factory(level=0.02, trend_per_day=0.0).centre_s == 20_000.0
    with pytest.raises(ValueError, match="centre_s"):
        drift_line_candidate(-1.0)
    with pytest.raises(ValueError, match="drift_fit"):
        check_fit("sometimes")


def test_only_the_coking_rise_is_taken_for_the_line() -> None:
    """With the line's trend free a candidate that moves f_coke over time is the line: not
    offered (``feed_coking_drift`` named with the wrong sign otherwise, lab/discover_drift.md)."""
    lib, _ = d.library_candidates()
    assert [c for c, cand in lib.items() if changes_coking(cand)] == ["feed_coking_drift"]
    assert changes_coking(drift_line_candidate(0.0))  # the line itself: the nuisance


def test_nuisance_entries_are_fitted_but_never_findings() -> None:
    line = Accepted(drift_line_candidate(0.0), np.zeros(2), np.zeros(2), 0, {}, nuisance=True)
    lib, _ = d.library_candidates()
    bias = Accepted(lib["sensor_bias:T_fp"], np.array([1.0]), np.array([0.1]), 1, {})
    acc = [line, bias]
    effs, theta = stacked(acc)
    assert [e.id for e in effs] == [DRIFT_LINE_ID, "sensor_bias:T_fp"]
    np.testing.assert_array_equal(theta, [0.0, 0.0, 1.0])
    np.testing.assert_array_equal(nuisance_mask(acc), [True, True, False])
    assert findings(acc) == [bias]
    assign(acc, np.array([0.01, 0.02, 9.0]), np.array([1.0, 2.0, 3.0]), nuisance_only=True)
    np.testing.assert_array_equal(line.theta, [0.01, 0.02])
    assert bias.theta[0] == 1.0  # held fixed in that fit: left as it was
    assign(acc, np.array([0.0, 0.0, 2.0]), np.array([1.0, 2.0, 3.0]), nuisance_only=False)
    assert bias.theta[0] == 2.0 and bias.stderr[0] == 3.0


def test_scan_limits_the_start_grid_to_the_candidates_parameters() -> None:
    """A parameter outside ``scan`` starts where it stands (no grid): a fit with the line free
    evaluates the candidate's grid only once, not once per line value."""
    data = d.from_batch(fcc_env.simulate_episodes([1003], 300))
    model = d.PhysicsModel()
    model.prepare(data, 180)
    lib, _ = d.library_candidates()
    effs = [drift_line_candidate(1500.0), lib["sensor_bias:T_rx"]]
    Y = data.stack(model.output_channels)
    sqrt_w = np.ones(len(model.output_channels))
    th0 = np.array([0.01, 0.02, 0.5])  # the line away from its null: a grid of 2 x 2 values
    free = np.ones(3, bool)
    n_grid = len({0.5, *lib["sensor_bias:T_rx"].params[0].grid})
    kw = {"max_iter": 0}  # the grid, then one batched step (the point and 3 perturbations)
    scanned = fit_effects(model, data, effs, th0, free, Y, 180, sqrt_w, **kw)
    only = fit_effects(
        model, data, effs, th0, free, Y, 180, sqrt_w, scan=[False, False, True], **kw
    )
    assert scanned.n_evals == 4 * n_grid + 4
    assert only.n_evals == n_grid + 4


def test_open_loop_results_do_not_depend_on_the_drift_fit() -> None:
    """Open-loop data carry no drift: the joint fit never starts, the report is the one the
    loop gave before (``drift_fit`` only recorded in the settings)."""
    effect = fx.parse("sensor_bias:T_rg2,bias=2")
    data = d.from_batch(fcc_env.simulate_episodes([1004], 1000, plant_effects=[effect]))
    cands = ["sensor_bias:T_rg2", "sensor_drift:T_rg2", "heat_loss:stage2"]
    reps = [
        d.discover(data, max_effects=1, plots=False, forms="never", candidates=cands, drift_fit=f)
        for f in ("joint", "fixed")
    ]
    a, b = (r.to_json() for r in reps)
    for r in (a, b):
        r.pop("elapsed_s")
        assert r["settings"].pop("drift_fit") in ("joint", "fixed")
    assert a == b
    assert reps[0].drift is None and reps[0].effects[0].id == "sensor_bias:T_rg2"


@pytest.mark.slow
def test_joint_fit_names_the_afterburn_that_leaked_into_the_estimate() -> None:
    """Default closed-loop program with a stage-1 afterburn factor of 1.3: it leaks into the
    drift estimate as a level, and fed as it is the loop named a T_fp bias
    (lab/discover_drift.md). With the line fitted jointly the afterburn is named first."""
    effect = fx.parse("afterburn:dilute1,factor=1.3")
    plant = fcc_env.PlantConfig.build(regulatory=True)
    data = d.from_batch(
        fcc_env.simulate_episodes([1001], 4000, plant=plant, plant_effects=[effect])
    )
    cands = ["afterburn:dilute1", "sensor_bias:T_fp", "afterburn:dilute_general", "air_split"]
    rep = d.discover(data, max_effects=1, plots=False, forms="never", candidates=cands)
    assert rep.drift is not None and rep.drift["used"] and "line" in rep.drift
    assert rep.effects and rep.effects[0].id == effect.effect_id
    assert rep.effects[0].params["factor"] == pytest.approx(1.3, rel=0.05)
    assert DRIFT_LINE_ID not in [e.id for e in rep.effects]
