"""The sensor-bias isolation bound (:mod:`evaluation.tracks.sensor_bound`).

The oracle is the simulated fault: the episode carries a bias of known size on a known
channel, so the profiled size must come back near it and the true channel must win.
"""

from __future__ import annotations

import numpy as np
import pytest

import fcc_env
from diagnosers.filters import FCCStateEstimator, UKFConfig
from evaluation.tracks.sensor_bound import bias_profiles, gaussian_loglik

PLANT = fcc_env.PlantConfig.build(regulatory=True)
ONSET, SIZE = 300, 4.0


@pytest.fixture(scope="module")
def profile():
    fault = fcc_env.FaultSpec(scenario="sensor-bias", channel="T_rg2", magnitude=SIZE, onset=ONSET)
    b = fcc_env.simulate_episodes([5001], ONSET + 60, plant=PLANT, fault=fault)
    est = FCCStateEstimator(PLANT.params, UKFConfig.matching(PLANT))
    return bias_profiles(est, b.observations[0], ONSET, ("T_rg2", "T_d1"), (10, 60))


def test_the_true_channel_wins_at_its_size(profile) -> None:
    i = profile.channels.index("T_rg2")
    assert abs(profile.size[i] - SIZE) < 0.5, profile.size
    llr = profile.llr("T_rg2")["T_d1"]
    assert llr[-1] > 10.0 and llr[-1] >= llr[0], llr  # evidence grows with the window
    # against no fault: a 4 °C step on a 0.3 °C channel, ~(4/0.3)²/2 nats a sample
    assert profile.loglik[i, -1] - profile.healthy[-1] > 500


def test_the_gaussian_density_is_the_textbook_one() -> None:
    rng = np.random.default_rng(0)
    L = np.tril(rng.normal(size=(3, 3))) + 3 * np.eye(3)
    S = L @ L.T
    e = rng.normal(size=3)
    white = np.linalg.solve(L, e)
    direct = -0.5 * e @ np.linalg.solve(S, e) - 0.5 * np.log(np.linalg.det((2 * np.pi) * S))
    assert gaussian_loglik(white[None], S[None])[0] == pytest.approx(direct, rel=1e-12)


def test_an_onset_without_room_for_the_window_is_refused() -> None:
    est = FCCStateEstimator(PLANT.params, UKFConfig.matching(PLANT))
    y = np.zeros((100, len(est.channels)))
    with pytest.raises(ValueError, match="onset"):
        bias_profiles(est, y, 90, ("T_rx",), (30,))
