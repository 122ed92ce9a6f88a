"""A public conformance check for diagnosers: :func:`check_diagnoser`.

What scikit-learn's ``check_estimator`` and Gymnasium's ``check_env`` do for their objects, this
does for a :class:`~diagnosers.Diagnoser`, yours or the library's::

    import diagnosers
    diagnosers.check_diagnoser(MyDetector())   # raises ConformanceError naming the failed check

It runs the contract checks the project's own tests run on every registered diagnoser: refusal of
unfitted use, scikit-learn style parameters (``get_params``, ``set_params``, ``clone``),
registration, ``fit``, the shapes and conventions of a :class:`~diagnosers.Detection`,
determinism, streaming equals batch, and a save/load round trip whose files hold no pickle.
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from diagnosers.bank.relations import read_channels
from diagnosers.contract import NotFittedError
from diagnosers.detection import UNKNOWN, Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.registry import diagnoser_class

__all__ = ["CHECKS", "ConformanceError", "check_diagnoser", "default_episodes"]

#: The checks :func:`check_diagnoser` runs, in order (the names its errors use).
CHECKS: tuple[str, ...] = (
    "unfitted use",
    "parameters",
    "registration",
    "fit",
    "detection contract",
    "stream = batch",
    "determinism",
    "save/load",
)


class ConformanceError(AssertionError):
    """A diagnoser broke the contract; the message names the check and the diagnoser."""

    def __init__(self, check: str, diagnoser: str, detail: str) -> None:
        self.check = check
        self.diagnoser = diagnoser
        super().__init__(f"{diagnoser} fails the {check!r} check of check_diagnoser: {detail}")


def default_episodes(
    n_train: int = 1500, n_test: int = 1200, *, closed_loop: bool = False
) -> tuple[list[Episode], Episode, list[Episode]]:
    """Small FCC-v0 episodes: ``(healthy training, faulty test, labelled faulty training)``.

    Two healthy episodes (seeds 1000, 1001), a test episode with fault ``f1`` from two thirds of
    it (seed 3), and eight labelled faulty episodes (``f1`` and ``f2``, onset at half) for the
    diagnosers that isolate or learn from faults: on seeds 11 and 12, and on the healthy seeds
    1000 and 1001, where each has its healthy noise twin (what a detector that learns from
    faults pairs; on its own training seeds a detector may not alarm at all). Two faults are a
    deliberate sample, not "the faults": two classes are what the contract needs, and they keep
    the checks fast. Simulating them takes well under a second.
    ``closed_loop``: the same on the closed-loop plant (``FCC-closedloop-v0``).
    """
    import fcc_env  # here: the diagnosers package does not need the simulator to import

    reg = True if closed_loop else None

    plant = fcc_env.PlantConfig.build(regulatory=reg)

    def sim(seeds: list[int], n: int, fault: Any = None) -> list[Episode]:
        return Episode.from_batch(fcc_env.simulate_episodes(seeds, n, fault=fault, plant=plant))

    train = sim([1000, 1001], n_train)
    [test] = sim([3], n_test, fcc_env.FaultSpec(scenario="f1", onset=2 * n_test // 3))
    faulty = [
        ep
        for scenario in ("f1", "f2")
        for ep in sim(
            [11, 12, 1000, 1001], n_test, fcc_env.FaultSpec(scenario=scenario, onset=n_test // 2)
        )
    ]
    return train, test, faulty


def _label(d: object) -> str:
    name = getattr(d, "name", "")
    return f"{type(d).__name__} ({name!r})" if name else type(d).__name__


def _same(a: Detection, b: Detection, atol: float) -> None:
    """Assert equal alarms, diagnoses and names, and close arrays (``atol`` 0: identical)."""
    np.testing.assert_array_equal(a.alarm, b.alarm, err_msg="alarm")
    assert a.signal_names == b.signal_names, f"signal_names {a.signal_names} != {b.signal_names}"
    for name in ("signal", "lower", "upper", "residual"):
        x, y = getattr(a, name), getattr(b, name)
        assert np.shape(x) == np.shape(y), f"{name} shape {np.shape(x)} != {np.shape(y)}"
        np.testing.assert_allclose(x, y, rtol=1e-12 if atol else 0.0, atol=atol, err_msg=name)
    assert a.class_names == b.class_names, f"class_names {a.class_names} != {b.class_names}"
    assert (a.diagnosis is None) == (b.diagnosis is None), "one detection has a diagnosis"
    if a.diagnosis is not None and b.diagnosis is not None:
        np.testing.assert_array_equal(a.diagnosis, b.diagnosis, err_msg="diagnosis")
        assert (a.class_scores is None) == (b.class_scores is None), "class_scores: one is None"
        if a.class_scores is not None:
            np.testing.assert_allclose(
                a.class_scores, b.class_scores, rtol=1e-12 if atol else 0.0, atol=atol
            )


def _alarm_is_outside(det: Detection, what: str) -> None:
    # An alarm filter (lrgf-glr's on_delay > 1) may hold back an exceedance, never invent one:
    # every alarm has some signal outside its limits (score > 1), not every exceedance an alarm.
    outside = np.any((det.signal < det.lower) | (det.signal > det.upper), axis=1)
    bad = np.flatnonzero(det.alarm & ~outside)
    assert bad.size == 0, (
        f"{what}: an alarm needs some signal outside [lower, upper]; samples {bad[:5].tolist()} "
        "alarm with every signal inside"
    )


@dataclass
class _Run:
    """What the checks share: the diagnoser under test, the data and the fitted instances."""

    original: Diagnoser
    train: list[Episode]
    test: Episode
    tmp_dir: Path
    fitted: Diagnoser | None = None
    detection: Detection | None = None

    def clone(self) -> Diagnoser:
        from sklearn.base import clone

        return clone(self.original)

    def fit_clone(self) -> Diagnoser:
        d = self.clone()
        out = d.fit(self.train)
        assert out is d, f"fit returned {out!r}, not the diagnoser itself"
        return d


def _expect_not_fitted(call: Callable[[], object], what: str) -> None:
    try:
        call()
    except NotFittedError:
        return
    except Exception as e:
        raise AssertionError(
            f"{what} on an unfitted diagnoser raised {type(e).__name__}: {e}; "
            "it must raise diagnosers.NotFittedError"
        ) from e
    raise AssertionError(f"{what} on an unfitted diagnoser did not raise NotFittedError")


def _check_unfitted(run: _Run) -> None:
    d, y0 = run.clone(), run.test.y[0]
    _expect_not_fitted(d.check_is_fitted, "check_is_fitted()")
    _expect_not_fitted(d.reset, "reset()")
    _expect_not_fitted(lambda: d.update(y0), "update(measurement)")
    _expect_not_fitted(lambda: d.detect(run.test), "detect(episode)")
    _expect_not_fitted(lambda: d.save(run.tmp_dir / "unfitted"), "save(path)")
    assert not (run.tmp_dir / "unfitted" / "config.json").exists(), "save wrote a config.json"


def _check_params(run: _Run) -> None:
    d = run.original
    params = d.get_params()
    assert isinstance(params, dict), f"get_params() returned a {type(params).__name__}"
    assert set(params) == set(d.param_names()), (
        f"get_params() keys {sorted(params)} != the keyword-only __init__ parameters "
        f"{sorted(d.param_names())}"
    )
    assert d.get_params(deep=True) == d.get_params(deep=False) == params, "deep changes params"
    try:
        json.dumps(params)
    except (TypeError, ValueError) as e:
        raise AssertionError(f"get_params() is not JSON-serialisable (save needs it): {e}") from e
    rebuilt = type(d)(**params)
    assert rebuilt.get_params() == params, "type(d)(**d.get_params()) has other parameters"
    assert rebuilt.set_params(**params) is rebuilt, "set_params did not return self"
    assert rebuilt.get_params() == params, "set_params(**get_params()) changed the parameters"
    unknown = set(type(d).fast_params()) - set(d.param_names())
    assert not unknown, f"fast_params() names unknown hyperparameters {sorted(unknown)}"
    twin = run.clone()
    assert type(twin) is type(d) and twin is not d, "sklearn.base.clone gave no twin"
    assert twin.get_params() == params, "sklearn.base.clone changed the parameters"


def _check_registration(run: _Run) -> None:
    d = run.original
    assert d.name, (
        "the class has no registry name: decorate it with @diagnosers.register('name') "
        "(Diagnoser.load rebuilds saved diagnosers by name)"
    )
    try:
        cls = diagnoser_class(d.name)
    except ValueError as e:
        raise AssertionError(str(e)) from e
    assert cls is type(d), f"the name {d.name!r} is registered to {cls}, not to {type(d)}"


def _check_fit(run: _Run) -> None:
    d = run.fit_clone()
    d.check_is_fitted()
    assert d.channels_ == run.train[0].channels, f"channels_ {d.channels_} != training channels"
    assert d.sample_time_s_ == run.train[0].sample_time_s, "sample_time_s_ != training's"
    names = d.signal_names_
    assert isinstance(names, tuple) and names and all(isinstance(n, str) for n in names), (
        f"signal_names_ must be a non-empty tuple of str, got {names!r}"
    )
    run.fitted = d


def _check_detection(run: _Run) -> None:
    d = run.fitted
    assert d is not None
    det = d.detect(run.test)
    assert isinstance(det, Detection), f"detect returned a {type(det).__name__}, not a Detection"
    n, k = run.test.n_samples, len(d.signal_names_)
    assert det.alarm.shape == (n,) and det.alarm.dtype == np.bool_, (
        f"alarm must be bool of shape ({n},), got {det.alarm.dtype} {det.alarm.shape}"
    )
    for name in ("signal", "lower", "upper"):
        shape = np.shape(getattr(det, name))
        assert shape == (n, k), f"{name} must have shape ({n}, {k}) (signal_names_), got {shape}"
    r = det.residual
    assert r.ndim == 2 and r.shape[0] == n and r.shape[1] >= 1, (
        f"residual must have shape ({n}, m >= 1), got {r.shape}"
    )
    assert det.signal_names == d.signal_names_, "Detection.signal_names != signal_names_"
    assert np.all(det.lower <= det.upper), "lower > upper on some sample"
    _alarm_is_outside(det, "detect")
    bands = d.band_view(run.test)
    if bands is not None:
        assert bands.alarm.shape == (n,) and bands.signal.shape == bands.lower.shape, (
            "band_view: alarm or signal/lower shapes are wrong"
        )
        _alarm_is_outside(bands, "band_view")
    if not d.isolates:
        assert det.diagnosis is None and det.class_scores is None and det.class_names == (), (
            "a diagnoser with isolates=False must leave diagnosis, class_scores, class_names empty"
        )
    else:
        classes = tuple(getattr(d, "classes_", ()))
        labels = {ep.scenario for ep in run.train if ep.fault_onset is not None}
        assert classes and set(classes) <= labels, (
            f"classes_ {classes} must be a non-empty tuple of the training fault labels {labels}"
        )
        assert det.class_names == classes, f"class_names {det.class_names} != classes_ {classes}"
        assert det.diagnosis is not None and det.diagnosis.shape == (n,), "diagnosis shape"
        np.testing.assert_array_equal(
            det.diagnosis != "", det.alarm, err_msg="diagnosis must be '' exactly when not alarmed"
        )
        odd = set(det.diagnosis[det.alarm].tolist()) - {*classes, UNKNOWN}
        assert not odd, f"diagnoses {sorted(odd)} are neither classes_ nor {UNKNOWN!r}"
        assert det.class_scores is not None and det.class_scores.shape == (n, len(classes)), (
            "class_scores must have shape (n_samples, len(classes_))"
        )
    run.detection = det


def _check_stream(run: _Run) -> None:
    d, batch = run.fitted, run.detection
    assert d is not None and batch is not None
    d.reset()
    decisions = [d.update(row) for row in run.test.y]
    classes = tuple(d.classes_) if d.isolates else None  # type: ignore[attr-defined]
    streamed = Detection.from_decisions(decisions, d.signal_names_, classes)
    try:
        _same(batch, streamed, atol=1e-9)
    except AssertionError as e:
        raise AssertionError(f"reset() + update() per sample differs from detect(): {e}") from e
    # detect() leaves no streaming state behind and reset() really resets
    again = d.detect(run.test)
    try:
        _same(batch, again, atol=0.0)
    except AssertionError as e:
        raise AssertionError(f"detect() after streaming differs from the first: {e}") from e
    d.reset()
    for t, row in enumerate(run.test.y[:50]):
        dec = d.update(row)
        assert dec.alarm == decisions[t].alarm and dec.diagnosis == decisions[t].diagnosis, (
            f"after reset(), update() at sample {t} decides otherwise than the first time"
        )
        np.testing.assert_allclose(
            dec.signal, decisions[t].signal, rtol=1e-12, atol=1e-9, err_msg="signal after reset"
        )
    d.reset()


def _check_determinism(run: _Run) -> None:
    assert run.detection is not None
    again = run.fit_clone().detect(run.test)
    try:
        _same(run.detection, again, atol=0.0)
    except AssertionError as e:
        raise AssertionError(
            "two fits of clones on the same data give different detections (seed every random "
            f"generator from a hyperparameter): {e}"
        ) from e


def _check_files(directory: Path) -> None:
    """Every saved file is readable without unpickling arbitrary objects."""
    for path in sorted(p for p in directory.rglob("*") if p.is_file()):
        if path.suffix == ".npz":
            with np.load(path, allow_pickle=False) as data:
                for key in data.files:
                    try:
                        data[key]
                    except ValueError as e:
                        raise AssertionError(f"{path.name}[{key!r}] holds objects: {e}") from e
        elif path.suffix == ".json":
            json.loads(path.read_text())
        elif path.suffix == ".pt":
            import torch

            torch.load(path, weights_only=True)
        else:
            head = path.read_bytes()[:2]
            is_pickle = len(head) == 2 and head[0] == 0x80 and 2 <= head[1] <= 5
            assert not is_pickle, f"{path.name} is a pickle; save plain arrays and JSON"


def _as_json(params: dict[str, object]) -> object:
    """``params`` as JSON gives them back (tuples become lists), for comparison."""
    return json.loads(json.dumps(params))


def _check_save_load(run: _Run) -> None:
    d, before = run.fitted, run.detection
    assert d is not None and before is not None
    path = run.tmp_dir / "model"
    d.save(path)
    _check_files(path)
    for loader in (Diagnoser.load, type(d).load):
        back = loader(path)
        assert type(back) is type(d), f"load gave a {type(back).__name__}"
        saved, loaded = _as_json(d.get_params()), _as_json(back.get_params())
        assert loaded == saved, f"the loaded parameters {loaded} differ from {saved}"
        assert back.channels_ == d.channels_, "the loaded channels_ differ"
        assert back.sample_time_s_ == d.sample_time_s_, "the loaded sample_time_s_ differs"
        try:
            _same(before, back.detect(run.test), atol=0.0)
        except AssertionError as e:
            raise AssertionError(
                f"the loaded diagnoser detects otherwise than the saved one (does _get_state "
                f"hold all the learned state?): {e}"
            ) from e


_RUNNERS: dict[str, Callable[[_Run], None]] = {
    "unfitted use": _check_unfitted,
    "parameters": _check_params,
    "registration": _check_registration,
    "fit": _check_fit,
    "detection contract": _check_detection,
    "stream = batch": _check_stream,
    "determinism": _check_determinism,
    "save/load": _check_save_load,
}


def check_diagnoser(
    diagnoser: Diagnoser,
    *,
    train: Sequence[Episode] | None = None,
    test: Episode | None = None,
    faulty_train: Sequence[Episode] | None = None,
    tmp_dir: str | Path | None = None,
) -> None:
    """Check that ``diagnoser`` keeps the diagnoser contract; raise on the first broken check.

    Args:
        diagnoser: an unfitted instance, built with the hyperparameters to check (for a fast
            check of a slow model, e.g. ``cls(**cls.fast_params())``). It is not modified: the
            checks fit clones of it (``sklearn.base.clone``).
        train: healthy training episodes (default: :func:`default_episodes`' FCC-v0 ones).
        test: the episode to detect on, ideally with a fault (default: FCC-v0 with ``f1``).
        faulty_train: labelled faulty episodes (``fault_onset`` and ``scenario`` set), added to
            ``train`` when the diagnoser isolates (:attr:`~diagnosers.Diagnoser.isolates`) or
            learns from faults (:attr:`~diagnosers.Diagnoser.learns_from_faults`).
        tmp_dir: where to save the model for the round trip (default: a temporary directory,
            removed afterwards).

    Checks, in the order of :data:`CHECKS`: unfitted ``check_is_fitted``, ``reset``,
    ``update``, ``detect`` and ``save`` raise :class:`~diagnosers.NotFittedError`;
    ``get_params``/``set_params`` round trip, are JSON-serialisable and ``sklearn.base.clone``
    gives a twin; the class is registered under its ``name``; ``fit`` returns ``self``; the
    detection's shapes, types and alarm/band/diagnosis conventions; ``reset()`` + ``update()``
    per sample equals ``detect()``; two fits give identical detections; ``save`` + ``load``
    detects identically, and the saved files hold no pickle.

    Raises:
        ConformanceError: (an ``AssertionError``) naming the diagnoser and the failed check; an
            exception raised by the diagnoser during a check is its cause.
        ValueError: ``diagnoser`` is not an unfitted :class:`~diagnosers.Diagnoser`.
    """
    label = _label(diagnoser)
    if not isinstance(diagnoser, Diagnoser):
        raise ValueError(f"check_diagnoser takes a diagnosers.Diagnoser, got {label}")
    if getattr(diagnoser, "_fitted_", False):
        raise ValueError(
            f"check_diagnoser takes an unfitted diagnoser; {label} is fitted: pass "
            "sklearn.base.clone(diagnoser) (or a new instance) instead"
        )
    labelled = diagnoser.isolates or diagnoser.learns_from_faults
    if train is None or test is None or (labelled and faulty_train is None):
        # a diagnoser that reads the controllers' channels gets closed-loop episodes
        default_train, default_test, default_faulty = default_episodes(
            closed_loop="u_F" in read_channels(diagnoser)
        )
        train = default_train if train is None else train
        test = default_test if test is None else test
        faulty_train = default_faulty if faulty_train is None else faulty_train
    training = list(train) + (list(faulty_train or ()) if labelled else [])
    with tempfile.TemporaryDirectory(prefix="check_diagnoser_") as scratch:
        run = _Run(
            diagnoser, training, test, Path(tmp_dir) if tmp_dir is not None else Path(scratch)
        )
        for check in CHECKS:
            try:
                _RUNNERS[check](run)
            except AssertionError as e:
                raise ConformanceError(check, label, str(e) or type(e).__name__) from e
            except Exception as e:
                raise ConformanceError(check, label, f"raised {type(e).__name__}: {e}") from e
