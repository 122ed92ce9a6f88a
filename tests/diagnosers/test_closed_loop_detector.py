"""The closed-loop detectors (``lrgf-glr-closed``, ``n4sid-glr-closed``) keep the diagnoser
contract on closed-loop episodes, and the harness skips them where their channels are missing."""

from __future__ import annotations

import numpy as np
import pytest

import diagnosers
from diagnosers.bank.relations import CLOSED_LOOP_RELATIONS, required_channels
from diagnosers.conformance import check_diagnoser, default_episodes
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


def test_n4sid_closed_preset_is_skipped_on_open_loop_tracks() -> None:
    assert {"T_rx_sp", "T_rg1_sp", "u_F"} <= required_channels("n4sid-glr-closed")
    assert not required_channels("n4sid-glr")  # the open-loop preset reads any channels
    names = ["n4sid-glr", "n4sid-glr-closed"]
    keep, _ = applicable(names, track_channels(TRACKS["paper"]), "on track paper")
    assert keep == ["n4sid-glr"]
    keep, _ = applicable(names, track_channels(TRACKS["closed"]), "on track closed")
    assert keep == names


def test_n4sid_closed_preset_fits_a_stable_predictor_on_closed_loop_data() -> None:
    # n4sid-glr at its defaults identifies an unstable predictor on these episodes (pole
    # magnitude 1.03, lab/monitors-lab.md); with the set points as inputs the loop is open
    train, test, _ = default_episodes(1500, 1200, closed_loop=True)
    det = diagnosers.make("n4sid-glr-closed").fit(train)
    assert [det.channels_[i] for i in det.u_idx_] == ["T_rx_sp", "T_rg1_sp"]
    assert {"u_F", "R_ar"} <= {det.channels_[i] for i in det.y_idx_}
    assert np.max(np.abs(det.model_.predictor_poles())) < 0.99
    alarm = det.detect(test).alarm  # f1 from sample 800
    assert alarm[:800].mean() < 0.02
    assert alarm[800:].mean() > 0.9
