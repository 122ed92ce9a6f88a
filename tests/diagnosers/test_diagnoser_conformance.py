"""Every registered diagnoser goes through the same contract checks (see diagnosers/contract.py).

The contract itself (unfitted use, parameters and ``sklearn.base.clone``, registration, fit,
the detection's conventions, streaming equals batch, determinism, save/load) is checked by the
public :func:`diagnosers.check_diagnoser`, which users run on their own diagnosers; this module
runs it on every registered diagnoser and adds what it does not cover (error messages, corrupt
saved files, the isolators' classes). Each diagnoser class's ``fast_params()`` classmethod gives
small, fast hyperparameters for these tests (e.g. few epochs for a neural model); the base class
returns ``{}`` (the defaults).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from synthetic import inject_step_fault, make_episode

import diagnosers
import fcc_env
from diagnosers import Diagnoser, Episode, NotFittedError, make
from diagnosers.bank.relations import required_channels


def _physical(name: str) -> bool:
    """A diagnoser whose classes are the registry's faults, modelled (``mmae``): synthetic
    labels mean nothing to it, so it is checked on simulated FCC episodes instead."""
    return bool(getattr(diagnosers.diagnoser_class(name), "physical_classes", False))


#: every registered diagnoser that reads FCC-v0's channels (closed-loop ones: see
#: tests/diagnosers/test_closed_loop_detector.py), but the physical ones
NAMES = [
    n
    for n in diagnosers.available()
    if required_channels(n) <= set(fcc_env.MEASUREMENT_NAMES) and not _physical(n)
]
#: the physical ones: check_diagnoser's default (simulated) episodes
PHYSICAL = [n for n in diagnosers.available() if _physical(n)]


def _params(name: str) -> dict:
    return dict(diagnosers.diagnoser_class(name).fast_params())


@pytest.mark.parametrize("name", NAMES)
def test_fast_params_are_public(name: str) -> None:
    cls = diagnosers.diagnoser_class(name)
    assert cls is type(make(name))
    assert set(cls.fast_params()) <= set(cls.param_names())


def test_diagnoser_class_unknown_name() -> None:
    with pytest.raises(ValueError, match=r"Unknown diagnoser 'nope'\. Available: \[.*'limits'"):
        diagnosers.diagnoser_class("nope")


def _build(name: str) -> Diagnoser:
    return make(name, **_params(name))


@pytest.fixture(scope="module")
def train() -> list[Episode]:
    return [make_episode(1500, seed=s) for s in (1, 2)]


@pytest.fixture(scope="module")
def test_episode() -> Episode:
    return inject_step_fault(make_episode(1200, seed=3), onset=800, magnitude=3.0)


@pytest.fixture(scope="module")
def train_faults() -> list[Episode]:
    """Labelled faulty training episodes for the diagnosers that isolate (two classes)."""
    return [
        inject_step_fault(make_episode(1200, seed=s), onset=600, magnitude=3.0, channel=ch)
        for ch in ("T_rx", "T_rg1")
        for s in (11, 12)
    ]


def _training(name: str, train: list[Episode], train_faults: list[Episode]) -> list[Episode]:
    """What the harness trains ``name`` on: healthy episodes, plus labelled faults if it isolates."""
    return train + train_faults if diagnosers.diagnoser_class(name).isolates else train


@pytest.fixture(scope="module")
def fitted(train: list[Episode], train_faults: list[Episode]) -> dict[str, Diagnoser]:
    """One fitted instance per diagnoser, shared by the read-only checks."""
    return {name: _build(name).fit(_training(name, train, train_faults)) for name in NAMES}


#: Isolators that name one fault of their own, which check_diagnoser's default closed-loop
#: episodes (f1, f2) do not carry: their contract is checked on their own fault's episodes
#: (``stiction-ccf``: tests/diagnosers/test_loop_monitors.py, on sticking-valve records;
#: ``stiction-ukf``, ``loop-offset``, ``air-deficit``: tests/diagnosers/test_catalogue_members.py).
OWN_FAULT_DATA = ("stiction-ccf", "stiction-ukf", "loop-offset", "air-deficit")


@pytest.mark.parametrize(
    "name",
    [
        *NAMES,
        *PHYSICAL,
        # closed-loop diagnosers: check_diagnoser simulates closed-loop episodes for them
        *(
            pytest.param(n, marks=pytest.mark.slow)
            for n in diagnosers.available()
            if n not in NAMES and n not in PHYSICAL and n not in OWN_FAULT_DATA
        ),
    ],
)
def test_check_diagnoser_passes(
    name: str, train: list[Episode], test_episode: Episode, train_faults: list[Episode]
) -> None:
    d = _build(name)
    if name in NAMES:
        diagnosers.check_diagnoser(d, train=train, test=test_episode, faulty_train=train_faults)
    else:
        diagnosers.check_diagnoser(d)
    with pytest.raises(NotFittedError):  # the checks fit clones, never the instance
        d.check_is_fitted()


def test_baselines_are_registered() -> None:
    assert {"limits", "pca", "arx-band"} <= set(NAMES)


@pytest.mark.parametrize("name", NAMES)
def test_not_fitted_errors(name: str, test_episode: Episode, tmp_path: Path) -> None:
    d = _build(name)
    with pytest.raises(NotFittedError, match="not fitted"):
        d.reset()
    with pytest.raises(NotFittedError, match="not fitted"):
        d.update(test_episode.y[0])
    with pytest.raises(NotFittedError, match="not fitted"):
        d.detect(test_episode)
    with pytest.raises(NotFittedError, match="not fitted"):
        d.save(tmp_path / "model")


@pytest.mark.parametrize("name", NAMES)
def test_diagnosis_conventions(
    name: str, fitted: dict[str, Diagnoser], test_episode: Episode
) -> None:
    d = fitted[name]
    det = d.detect(test_episode)
    n = test_episode.n_samples
    if not d.isolates:
        assert det.diagnosis is None and det.class_scores is None and det.class_names == ()
        return
    classes = d.classes_  # type: ignore[attr-defined]
    assert classes == ("step_T_rg1", "step_T_rx")  # the labelled training faults
    assert det.class_names == classes
    assert det.diagnosis is not None and det.diagnosis.shape == (n,)
    np.testing.assert_array_equal(det.diagnosis != "", det.alarm)  # "" exactly when not alarmed
    assert set(det.diagnosis[det.alarm].tolist()) <= {*classes, diagnosers.UNKNOWN}
    assert det.class_scores is not None and det.class_scores.shape == (n, len(classes))


@pytest.mark.parametrize("name", NAMES)
def test_load_rejects_foreign_or_corrupted_directories(
    name: str, fitted: dict[str, Diagnoser], tmp_path: Path
) -> None:
    path = fitted[name].save(tmp_path / "model")
    cfg = path / "config.json"
    good = json.loads(cfg.read_text())

    cfg.write_text(json.dumps({"format": "someone-elses-model", "weights": [1, 2]}))
    with pytest.raises(ValueError, match="not a saved diagnoser of this library"):
        Diagnoser.load(path)

    cfg.write_text('{"format": "fcc-diagnoser", "format_ver')  # truncated
    with pytest.raises(ValueError, match="not valid JSON"):
        Diagnoser.load(path)

    cfg.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(ValueError, match="not valid JSON"):
        Diagnoser.load(path)

    cfg.write_text(json.dumps({**good, "format_version": 999}))
    with pytest.raises(ValueError, match="format_version 999 is not supported"):
        Diagnoser.load(path)

    cfg.write_text(json.dumps({k: v for k, v in good.items() if k != "params"}))
    with pytest.raises(ValueError, match="'params' is missing"):
        Diagnoser.load(path)

    cfg.write_text(json.dumps({**good, "diagnoser": "no-such-diagnoser"}))
    with pytest.raises(ValueError, match="Unknown diagnoser 'no-such-diagnoser'"):
        Diagnoser.load(path)

    cfg.write_text(json.dumps(good))
    (path / "state.npz").write_bytes(b"not a zip file")
    with pytest.raises(ValueError, match="not a numeric state file"):
        Diagnoser.load(path)

    with pytest.raises(ValueError, match=r"config\.json is missing"):
        Diagnoser.load(tmp_path / "empty")


def test_load_through_the_wrong_class_raises(fitted: dict[str, Diagnoser], tmp_path: Path) -> None:
    path = fitted["limits"].save(tmp_path / "model")
    with pytest.raises(ValueError, match="holds a 'limits' diagnoser, not a PCADetector"):
        type(fitted["pca"]).load(path)


def test_make_rejects_unknown_name() -> None:
    with pytest.raises(ValueError, match=r"Unknown diagnoser 'nope'\. Available: \[.*'limits'"):
        make("nope")


@pytest.mark.parametrize("name", NAMES)
def test_make_rejects_unknown_hyperparameter(name: str) -> None:
    with pytest.raises(ValueError, match=r"Unknown hyperparameter\(s\) \['not_a_param'\]"):
        make(name, not_a_param=1)


@pytest.mark.parametrize("name", NAMES)
def test_rejects_mismatched_channels(
    name: str, fitted: dict[str, Diagnoser], test_episode: Episode
) -> None:
    d = fitted[name]
    swapped = Episode(
        y=test_episode.y[:, ::-1],
        channels=test_episode.channels[::-1],
        sample_time_s=test_episode.sample_time_s,
    )
    with pytest.raises(ValueError, match="differ from the training channels"):
        d.detect(swapped)
    with pytest.raises(ValueError, match="differ from the training channels"):
        d.band_view(swapped)
    with pytest.raises(ValueError, match="measurement must have shape"):
        d.update(test_episode.y[0, :3])
    d.reset()
