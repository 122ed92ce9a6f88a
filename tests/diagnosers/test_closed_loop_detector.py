"""The closed-loop detector (``lrgf-glr-closed``) keeps the diagnoser contract on closed-loop
episodes, and the harness skips it where its channels are missing."""

from __future__ import annotations

import pytest

import diagnosers
from diagnosers.bank.relations import CLOSED_LOOP_RELATIONS, required_channels
from diagnosers.conformance import check_diagnoser
from evaluation.tracks.board import applicable, track_channels
from evaluation.tracks.catalogue import TRACKS


def test_closed_preset_reads_the_manipulated_variables() -> None:
    need = required_channels("lrgf-glr-closed")
    assert {"u_F", "R_ar"} <= need
    det = diagnosers.make("lrgf-glr-closed")
    assert type(det).DEFAULT_RELATIONS == CLOSED_LOOP_RELATIONS


def test_harness_skips_a_detector_without_its_channels() -> None:
    names = ["limits", "lrgf-glr-closed"]
    keep, skipped = applicable(names, track_channels(TRACKS["paper"]), "on track paper")
    assert keep == ["limits"]
    assert skipped == ["lrgf-glr-closed: skipped on track paper (no channel u_F)"]
    names = ["limits", "lrgf-glr-closed", "lrgf-glr"]
    keep, skipped = applicable(names, track_channels(TRACKS["closed"]), "on track closed")
    assert keep == ["limits", "lrgf-glr-closed", "lrgf-glr"] and not skipped


@pytest.mark.slow
def test_closed_preset_conforms_on_closed_loop_episodes() -> None:
    cls = diagnosers.diagnoser_class("lrgf-glr-closed")
    check_diagnoser(cls(**cls.fast_params()))  # picks closed-loop episodes: it reads u_F
