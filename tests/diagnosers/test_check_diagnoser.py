"""``diagnosers.check_diagnoser``: passes on the library's diagnosers and the worked example, and
fails, naming the check, on diagnosers that break the contract on purpose.

The broken diagnosers are registered only while a test runs (``_registered``), so that
``diagnosers.available()``, which other test modules parametrise over, never lists them.
"""

from __future__ import annotations

import re
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from synthetic import inject_step_fault, make_episode

import diagnosers
from diagnosers import ConformanceError, Decision, Detection, Diagnoser, Episode, registry
from diagnosers.conformance import CHECKS, default_episodes

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def episodes() -> tuple[list[Episode], Episode, list[Episode]]:
    return default_episodes()


def _check(d: Diagnoser, episodes: tuple[list[Episode], Episode, list[Episode]]) -> None:
    train, test, faulty = episodes
    diagnosers.check_diagnoser(d, train=train, test=test, faulty_train=faulty)


@pytest.mark.parametrize("name", ["limits", "pca", "arx-band", "lrgf-mem"])
def test_passes_on_the_library_diagnosers(name: str, episodes) -> None:
    cls = diagnosers.diagnoser_class(name)
    d = cls(**cls.fast_params())
    _check(d, episodes)
    # the instance itself is left unfitted: the checks fit clones of it
    with pytest.raises(diagnosers.NotFittedError):
        d.check_is_fitted()


def test_passes_on_the_worked_example_with_default_episodes(tmp_path: Path) -> None:
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    from examples.cusum_diagnoser import CUSUMDiagnoser

    diagnosers.check_diagnoser(CUSUMDiagnoser(channel="T_rx"), tmp_dir=tmp_path)
    assert (tmp_path / "model" / "config.json").is_file()


def test_passes_on_given_synthetic_episodes() -> None:
    train = [make_episode(600, seed=s) for s in (1, 2)]
    test = inject_step_fault(make_episode(500, seed=3), onset=300)
    diagnosers.check_diagnoser(diagnosers.make("limits"), train=train, test=test)


def test_refuses_a_fitted_instance_or_another_object(episodes) -> None:
    fitted = diagnosers.make("limits").fit(episodes[0])
    with pytest.raises(
        ValueError,
        match=r"takes an unfitted diagnoser; LimitChecker \('limits'\) is fitted: pass sklearn",
    ):
        diagnosers.check_diagnoser(fitted)
    with pytest.raises(ValueError, match=r"takes a diagnosers\.Diagnoser, got str"):
        diagnosers.check_diagnoser("limits")  # type: ignore[arg-type]


# ---- deliberately broken diagnosers --------------------------------------------------------------
class ZBand(Diagnoser):
    """A correct minimal detector: every channel against mean ± h standard deviations."""

    def __init__(self, *, h: float = 5.0) -> None:
        self.h = h

    def _fit(self, episodes: list[Episode]) -> None:
        y = np.concatenate([ep.y for ep in episodes])
        self.mean_, self.std_ = y.mean(axis=0), y.std(axis=0) + 1e-12
        self.signal_names_ = tuple(self.channels_)

    def _get_state(self) -> dict[str, np.ndarray]:
        return {"mean": self.mean_, "std": self.std_}

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.mean_, self.std_ = state["mean"], state["std"]
        self.signal_names_ = tuple(self.channels_)

    def _reset(self) -> None:
        pass

    def _update(self, y: np.ndarray) -> Decision:
        lo, hi = self.mean_ - self.h * self.std_, self.mean_ + self.h * self.std_
        alarm = bool(np.any((y < lo) | (y > hi)))
        return Decision(alarm=alarm, signal=y, lower=lo, upper=hi, residual=y - self.mean_)

    def _detect(self, y: np.ndarray) -> Detection:
        n = len(y)
        lo = np.tile(self.mean_ - self.h * self.std_, (n, 1))
        hi = np.tile(self.mean_ + self.h * self.std_, (n, 1))
        return Detection(
            alarm=np.any((y < lo) | (y > hi), axis=1),
            signal=y,
            lower=lo,
            upper=hi,
            residual=y - self.mean_,
            signal_names=self.signal_names_,
        )


class StreamDisagrees(ZBand):
    def _update(self, y: np.ndarray) -> Decision:
        dec = super()._update(y)
        return Decision(dec.alarm, dec.signal + 1e-3, dec.lower, dec.upper, dec.residual)


class LosesState(ZBand):
    def _get_state(self) -> dict[str, np.ndarray]:
        return {"mean": self.mean_}  # std_ is not saved ...

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.mean_, self.std_ = state["mean"], np.ones_like(state["mean"])  # ... and made up
        self.signal_names_ = tuple(self.channels_)


class NotDeterministic(ZBand):
    def _fit(self, episodes: list[Episode]) -> None:
        super()._fit(episodes)
        self.mean_ = self.mean_ + np.random.default_rng().normal(0.0, 1e-6, self.mean_.shape)


class NoRefusal(ZBand):
    def _check_fitted(self) -> None:
        pass  # uses an unfitted model instead of raising NotFittedError


@contextmanager
def _registered(cls: type[Diagnoser]) -> Iterator[Diagnoser]:
    """``cls()`` registered under a test-only name for the duration (load needs the name)."""
    name = f"test-{cls.__name__.lower()}"
    diagnosers.register(name)(cls)
    try:
        yield cls()
    finally:
        registry.unregister(name)


def test_the_minimal_detector_passes(episodes) -> None:
    with _registered(ZBand) as d:
        _check(d, episodes)


@pytest.mark.parametrize(
    ("cls", "check", "detail"),
    [
        (NoRefusal, "unfitted use", "did not raise NotFittedError|it must raise"),
        (StreamDisagrees, "stream = batch", r"update\(\) per sample differs from detect\(\)"),
        (NotDeterministic, "determinism", "two fits of clones"),
        (LosesState, "save/load", "the loaded diagnoser detects otherwise"),
    ],
)
def test_fails_naming_the_check(cls: type[Diagnoser], check: str, detail: str, episodes) -> None:
    assert check in CHECKS
    with _registered(cls) as d, pytest.raises(ConformanceError) as info:
        _check(d, episodes)
    err = info.value
    assert isinstance(err, AssertionError) and err.check == check
    assert f"{cls.__name__} ('test-{cls.__name__.lower()}') fails the {check!r} check" in str(err)
    assert err.diagnoser.startswith(cls.__name__)
    assert re.search(detail, str(err)), str(err)


def test_an_unregistered_class_fails_registration(episodes) -> None:
    with pytest.raises(ConformanceError, match=r"ZBand fails the 'registration' check.*register"):
        _check(ZBand(), episodes)


def test_a_temporary_registration_leaves_no_trace() -> None:
    # the broken diagnosers above must not reach the suites that run every registered name
    with _registered(NoRefusal):
        assert "test-norefusal" in diagnosers.available()
    assert "test-norefusal" not in diagnosers.available()
    assert NoRefusal.name == ""
    registry.unregister("never-registered")  # a no-op
