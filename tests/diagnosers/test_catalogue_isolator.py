"""``catalogue-isolator``: the composition of its members' names (confirmation, hold, the
answer as a trained label or ``unknown``), its parameter checks, and a fit on pair labels.

The contract (stream = batch, save/load, ...) is checked with the other physical isolators in
``test_diagnoser_conformance.py`` (``physical_classes``)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import diagnosers
import fcc_env
from diagnosers import Episode
from diagnosers.isolation.catalogue_isolator import signal_fault
from diagnosers.isolation.composition import Composition


def _run(comp: Composition, alarms: list[list[bool]], names: list[list[str]]) -> list[str]:
    return [comp.step(a, n)[1] for a, n in zip(alarms, names, strict=True)]


def test_a_name_counts_after_confirm_samples_in_a_row() -> None:
    comp = Composition([("a",)], ("a",), confirm=3, hold=True)
    out = _run(comp, [[True]] * 4, [["a"], ["a"], ["a"], ["a"]])
    assert out == ["unknown", "unknown", "a", "a"]
    comp = Composition([("a",)], ("a",), confirm=3, hold=True)
    # a break restarts the count
    assert _run(comp, [[True]] * 4, [["a"], [""], ["a"], ["a"]]) == ["unknown"] * 4


def test_two_members_name_a_pair_in_either_order() -> None:
    for first, second in ((0, 1), (1, 0)):
        comp = Composition([("a",), ("b",)], ("a+b", "a"), confirm=1, hold=True)
        names = [["", ""], ["", ""]]
        names[0][first] = ("a", "b")[first]
        names[1][second] = ("a", "b")[second]
        out = _run(comp, [[True, True]] * 2, names)
        assert out[-1] == "a+b"
        assert comp.named()[0] == ("a", "b")[first]  # first confirmed first


def test_hold_keeps_a_name_after_its_member_falls_silent() -> None:
    held = Composition([("a",)], ("a",), confirm=1, hold=True)
    free = Composition([("a",)], ("a",), confirm=1, hold=False)
    seq = ([[True], [False], [False]], [["a"], [""], [""]])
    assert _run(held, *seq) == ["a", "a", "a"]
    assert _run(free, *seq) == ["a", "", ""]


def test_a_set_that_is_no_trained_label_is_unknown() -> None:
    # one name of a pair-only training set, three names, an untrained pair: abstain
    comp = Composition([("a",), ("b",), ("c",)], ("a+b",), confirm=1, hold=True)
    assert comp.step([True, False, False], ["a", "", ""]) == (True, "unknown")
    assert comp.step([False, True, False], ["", "b", ""]) == (True, "a+b")
    assert comp.step([False, False, True], ["", "", "c"]) == (True, "unknown")
    comp = Composition([("a",), ("c",)], ("a+b", "a"), confirm=1, hold=True)
    assert _run(comp, [[True, True]], [["a", "c"]]) == ["unknown"]


def test_a_name_the_member_does_not_claim_is_no_evidence() -> None:
    comp = Composition([("a",), ("b",)], ("a", "b", "a+b"), confirm=1, hold=True)
    # member 0 says b (not its class), member 1 says a: nothing is confirmed
    assert comp.step([True, True], ["b", "a"]) == (True, "unknown")
    assert comp.named() == ()


def test_a_member_replaces_its_own_name_and_reset_forgets() -> None:
    comp = Composition([("a", "c")], ("a", "c"), confirm=2, hold=True)
    out = _run(comp, [[True]] * 5, [["a"], ["a"], ["c"], ["c"], ["c"]])
    assert out == ["unknown", "a", "a", "c", "c"]
    comp.reset()
    assert comp.named() == () and comp.step([False], [""]) == (False, "")


def test_a_member_that_names_several_adds_each_confirmed_name() -> None:
    seq = ([[True]] * 4, [["a"], ["a"], ["b"], ["b"]])
    one = Composition([("a", "b")], ("a", "b", "a+b"), confirm=2, hold=True)
    several = Composition([("a", "b")], ("a", "b", "a+b"), confirm=2, hold=True, several=[True])
    assert _run(one, *seq)[-1] == "b"
    assert _run(several, *seq)[-1] == "a+b"


def test_a_confirmed_verdict_outside_its_classes_clears_a_members_name() -> None:
    # a model member first reads a valve bias, later (better) a sensor bias it does not claim
    comp = Composition([("valve-bias",)], ("valve-bias",), confirm=2, hold=True)
    seq = [["valve-bias"]] * 3 + [["sensor-bias"]] * 2
    assert _run(comp, [[True]] * 5, seq) == ["unknown", *["valve-bias"] * 3, "unknown"]


def test_a_name_may_need_a_run_of_its_own() -> None:
    # the model's valve bias needs a long run (a sensor bias imitates it at first), its f1 not
    comp = Composition(
        [("f1", "valve-bias")],
        ("f1", "valve-bias"),
        confirm=4,
        hold=True,
        name_confirms=[{"f1": 2}],
    )
    assert _run(comp, [[True]] * 3, [["valve-bias"]] * 3) == ["unknown"] * 3
    comp.reset()
    assert _run(comp, [[True]] * 3, [["f1"]] * 3) == ["unknown", "f1", "f1"]


def test_a_deferring_member_is_no_evidence_while_the_other_names_its_own_fault() -> None:
    comp = Composition(
        [("sensor-bias",), ("valve-bias",)],
        ("sensor-bias", "valve-bias"),
        confirm=2,
        hold=True,
        defers=[(1,), ()],
    )
    both = [["sensor-bias", "valve-bias"]] * 3
    assert _run(comp, [[True, True]] * 3, both)[-1] == "valve-bias"
    # the model names a fault it does not claim: the sensor check's word counts again
    comp.reset()
    free = [["sensor-bias", "sensor-bias"]] * 3
    assert _run(comp, [[True, True]] * 3, free)[-1] == "sensor-bias"


def test_a_name_confirmed_since_the_others_alarm_began_is_dropped_as_its_echo() -> None:
    # the sensor check (confirm 1) names a bias while the model is alarmed but undecided; the
    # model then confirms f1: the bias was f1's echo. A name held before its alarm stays.
    def comp() -> Composition:
        return Composition(
            [("sensor-bias",), ("f1",)],
            ("f1", "sensor-bias+f1"),
            confirm=1,
            hold=True,
            defers=[(1,), ()],
            confirms=[1, 2],
        )

    echo = [["sensor-bias", "unknown"]] + [["sensor-bias", "f1"]] * 2
    assert _run(comp(), [[True, True]] * 3, echo) == ["unknown", "unknown", "f1"]
    before = [["sensor-bias", ""]] + [["", "f1"]] * 2
    alarms = [[True, False], [False, True], [False, True]]
    assert _run(comp(), alarms, before)[-1] == "sensor-bias+f1"


def test_a_run_begun_before_the_others_alarm_is_not_its_echo() -> None:
    # the model says f1 from sample 0 (confirm 4); a sticking valve's member alarms at sample 2
    # and confirms at 3. Deferring every run, f1 is never confirmed; with precedes=1, the f1
    # run began 2 samples before that alarm (more than 1): f1 came first and is named.
    def comp(first: int | None) -> Composition:
        return Composition(
            [("f1",), ("valve-stiction",)],
            ("f1+valve-stiction",),
            confirm=4,
            hold=True,
            defers=[(1,), ()],
            confirms=[4, 2],
            precedes=[first, None],
        )

    alarms = [[True, False]] * 2 + [[True, True]] * 4
    names = [["f1", ""]] * 2 + [["f1", "valve-stiction"]] * 4
    assert _run(comp(None), alarms, names)[-1] == "unknown"
    assert _run(comp(1), alarms, names)[-1] == "f1+valve-stiction"
    # a run begun within ``precedes`` of the alarm stays deferred: an echo
    assert _run(comp(2), alarms, names)[-1] == "unknown"


def test_signal_fault_reads_a_registered_fault_from_a_signal_name() -> None:
    assert signal_fault("glr[valve-bias,30]") == "valve-bias"
    assert signal_fault("glr[f1,300]") == "f1"
    assert signal_fault("cusum[nis]") is None
    assert signal_fault("T2") is None


@pytest.mark.parametrize(
    "params, match",
    [
        ({"members": []}, "members"),
        ({"members": [{"name": "ukf-glr", "params": {}}]}, r"members\[0\]"),
        ({"members": [{"name": "nope", "params": {}, "classes": ["f1"]}]}, "nope"),
        ({"members": [{"name": "limits", "params": {}, "classes": ["f9"]}]}, "f9"),
        ({"members": [{"name": "limits", "params": {"alpha": 7}, "classes": ["f1"]}]}, "alpha"),
        ({"confirm": 0}, "confirm"),
        (
            {"members": [{"name": "limits", "params": {}, "classes": ["f1"], "several": 1}]},
            "several",
        ),
        (
            {"members": [{"name": "limits", "params": {}, "classes": ["f1"], "defers_to": ["x"]}]},
            "defers_to",
        ),
        (
            {
                "members": [
                    {"name": "limits", "params": {}, "classes": ["f1"], "confirm_names": {"f2": 5}}
                ]
            },
            "confirm_names",
        ),
        (
            {
                "members": [
                    {"name": "limits", "params": {}, "classes": ["f1"], "confirm_names": {"f1": 0}}
                ]
            },
            "confirm_names",
        ),
        (
            {"members": [{"name": "limits", "params": {}, "classes": ["f1"], "precedes": -1}]},
            r"precedes=-1",
        ),
    ],
)
def test_bad_settings_are_refused_by_name(params: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        diagnosers.make("catalogue-isolator", **params).validate_params()


def _sim(seeds: list[int], n: int, fault: fcc_env.FaultSpec | None = None) -> list[Episode]:
    return Episode.from_batch(fcc_env.simulate_episodes(seeds, n, fault=fault))


def test_pair_labels_train_each_member_on_its_own_part() -> None:
    pair = fcc_env.FaultSpec(
        scenario="concurrent",
        parts=(
            fcc_env.FaultSpec(scenario="f1", onset=300),
            fcc_env.FaultSpec(scenario="f2", onset=500),
        ),
    )
    faulty = [dataclasses.replace(ep, scenario="f1+f2") for ep in _sim([11], 800, pair)]
    iso = diagnosers.make(
        "catalogue-isolator", **diagnosers.diagnoser_class("catalogue-isolator").fast_params()
    )
    iso.fit(_sim([1000, 1001], 800) + faulty)
    assert iso.classes_ == ("f1+f2",)
    assert iso.member_names_ == ("ukf-glr",)
    det = iso.detect(faulty[0])
    # one member names one fault at a time: never the pair, so it abstains or stays silent
    assert set(det.diagnosis.tolist()) <= {"", "unknown"}
    assert np.array_equal(det.diagnosis != "", det.alarm)
