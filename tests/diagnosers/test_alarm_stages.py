"""Every alarm stage follows :class:`~diagnosers.stages.alarm_stage.AlarmStage`, and the LRGF
families run theirs through :class:`~diagnosers.lrgf.bank_detector.BankDetector`'s skeleton."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from diagnosers.lrgf.bank_detector import BankDetector
from diagnosers.lrgf.lrgf_glr import GLR_CONSTRAINTS, GLR_DEFAULTS, LRGFGLR
from diagnosers.lrgf.lrgf_mem import LRGFMEM, PARAMETER_CONSTRAINTS
from diagnosers.stages.alarm_stage import AlarmStage
from diagnosers.stages.baseline import HeldBaseline
from diagnosers.stages.directional_stage import DirectionalStage
from diagnosers.stages.ewma_stage import EWMAStage

K = 3
DIRECTIONS = np.array([[1.0, 0.0, 0.0], [0.0, -0.6, 0.8]])
WARM_UP = 40


def _records(n: int, seed: int, length: int = 800) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.standard_normal((length, K)) for _ in range(n)]


def _baseline() -> HeldBaseline:
    baseline = HeldBaseline(lam=0.01, hold=0.5, settle=50)
    baseline.bind([np.array([0]), np.array([1]), np.array([2])], np.array([3, 4, 5]), [])
    return baseline


def _ewma(alarm_filter: str) -> Callable[[], EWMAStage]:
    return lambda: EWMAStage(alarm_filter=alarm_filter, false_alarm_target=0.02)


def _directional(**kw: Any) -> Callable[[], DirectionalStage]:
    return lambda: DirectionalStage(false_alarm_target=0.02, glr_window=30, **kw)


#: (a fresh unfitted stage, how it is fitted on healthy records)
STAGES: dict[str, tuple[Callable[[], Any], Callable[[Any, list[np.ndarray]], Any]]] = {
    **{
        f"ewma-{f}": (_ewma(f), lambda s, n: s.fit(n).set_band(np.full(K, 2.5)))
        for f in ("none", "ewma", "ewma-t2")
    },
    **{
        f"directional-{st}": (_directional(statistic=st), lambda s, n: s.fit(n, DIRECTIONS))
        for st in ("t2", "directional", "glr", "cusum")
    },
    "directional-on-delay": (_directional(on_delay=3), lambda s, n: s.fit(n, DIRECTIONS)),
    "directional-baseline": (_directional(baseline=_baseline()), lambda s, n: s.fit(n, DIRECTIONS)),
    "t2-centred": (_directional(statistic="t2", centered=True), lambda s, n: s.fit(n)),
}


def _fitted(name: str) -> Any:
    make, fit = STAGES[name]
    stage = make()
    fit(stage, [r + 0.1 for r in _records(3, 0)])  # an offset: the centred T² has a centre
    return stage


def _record() -> dict[str, np.ndarray]:
    """A record with a fault along the second direction from sample 400."""
    e = _records(1, 7)[0] + np.where(np.arange(800) >= 400, 1.5, 0.0)[:, None] * DIRECTIONS[1]
    centre = np.linspace(0.0, 1.0, len(e))[:, None] * np.ones(K)
    return {"e": e, "output": centre + e, "centre": centre, "residual": e}


@pytest.mark.parametrize("name", sorted(STAGES))
def test_every_stage_follows_the_protocol(name: str) -> None:
    stage = _fitted(name)
    assert isinstance(stage, AlarmStage)
    assert list(type(stage).CONSTRAINTS) == list(type(stage).DEFAULTS)  # one constraint each
    labels = ("a", "b", "c") if isinstance(stage, EWMAStage) else ("f1", "f2")
    names = stage.signal_names(labels)
    r = _record()
    parts = {"output": r["output"], "centre": r["centre"]}
    batch = stage.detect(r["e"], warm_up=WARM_UP, residual=r["residual"], names=names, **parts)
    assert batch.signal.shape == (len(r["e"]), len(names)) and batch.signal_names == names
    stage.reset()
    rows = [
        stage.step(
            r["e"][k],
            warm=k < WARM_UP,
            residual=r["residual"][k],
            **{p: v[k] for p, v in parts.items()},
        )
        for k in range(len(r["e"]))
    ]
    np.testing.assert_array_equal([d.alarm for d in rows], batch.alarm)
    # the batch T² of lrgf-glr's stage is vectorised: equal up to rounding
    np.testing.assert_allclose([d.signal for d in rows], batch.signal, rtol=1e-12, atol=1e-12)
    for field in ("lower", "upper", "residual"):
        np.testing.assert_array_equal([getattr(d, field) for d in rows], getattr(batch, field))
    assert not batch.alarm[:WARM_UP].any() and batch.alarm[400:].mean() > batch.alarm[:400].mean()
    if name != "ewma-none":  # the band rule reads the output, not the (zeroed) warm-up error
        garbage = r["e"].copy()
        garbage[:WARM_UP] = 99.0  # the warm-up reads as zero whatever it holds
        again = stage.detect(garbage, warm_up=WARM_UP, residual=r["residual"], names=names, **parts)
        np.testing.assert_array_equal(again.signal, batch.signal)


@pytest.mark.parametrize("name", sorted(STAGES))
def test_every_stage_state_round_trips(name: str) -> None:
    stage = _fitted(name)
    state = {k: np.asarray(v) for k, v in stage.get_state().items()}
    again = STAGES[name][0]()
    again.set_state(state)
    if isinstance(stage, EWMAStage):
        again.set_band(np.full(K, 2.5))
    r = _record()
    kw = {"warm_up": WARM_UP, "residual": r["residual"], "names": ("x",) * 9}
    kw |= {"output": r["output"], "centre": r["centre"]}
    a, b = stage.detect(r["e"], **kw), again.detect(r["e"], **kw)
    for field in ("alarm", "signal", "lower", "upper", "residual"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    missing = next(iter(state))
    with pytest.raises(ValueError, match=f"lacks array '{missing}'"):
        STAGES[name][0]().set_state({k: v for k, v in state.items() if k != missing})


@pytest.mark.parametrize("family", [LRGFMEM, LRGFGLR])
def test_the_families_leave_the_skeleton_to_the_bank_detector(family: type[BankDetector]) -> None:
    skeleton = {"_reset", "_update", "_detect", "_get_state", "_set_state"}
    assert not skeleton & set(vars(family)), sorted(skeleton & set(vars(family)))
    assert skeleton <= set(vars(BankDetector))


def test_the_families_take_the_stage_hyperparameters_from_the_stage() -> None:
    for family, constraints in ((LRGFMEM, PARAMETER_CONSTRAINTS), (LRGFGLR, GLR_CONSTRAINTS)):
        stage = family.STAGE
        assert {k: family.DEFAULTS[k] for k in stage.DEFAULTS} == dict(stage.DEFAULTS)
        assert all(constraints[k] is c for k, c in stage.CONSTRAINTS.items())
    assert LRGFGLR.DEFAULTS is GLR_DEFAULTS
