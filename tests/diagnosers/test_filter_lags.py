"""The filter's thermocouple lag states (``UKFConfig.sensor_lags``): on a plant whose T_rx
reading lags by 60 s the lag-aware filter learns the coefficient and whitens the innovations
the plain one leaves coloured; on a lag-free plant it learns no lag. Training seeds only."""

from __future__ import annotations

import math

import numpy as np
import pytest

import fcc_env
from diagnosers.filters import FCCStateEstimator, UKFConfig
from fcc_env import effects as fx

N, SKIP = 1500, 300
SEEDS = [1000, 1001]


def _observations(lag_s: float | None) -> np.ndarray:
    effects = [fx.make("sensor_lag:T_rx", tau_s=lag_s)] if lag_s else []
    b = fcc_env.simulate_episodes(SEEDS, N, plant_effects=effects)
    return np.asarray(b.observations, dtype=np.float64)


def test_a_lagged_reading_is_learnt_and_its_innovations_whitened() -> None:
    y = _observations(60.0)
    plain = FCCStateEstimator(fcc_env.FCCParams()).filter(y, innovation_cov=False)
    lagged = FCCStateEstimator(fcc_env.FCCParams(), UKFConfig(sensor_lags=("T_rx",))).filter(
        y, innovation_cov=False
    )
    a = lagged.state("lag_coef[T_rx]")[:, -1]
    assert np.allclose(a, math.exp(-10.0 / 60.0), atol=0.05)
    nis_plain = plain.nis[:, SKIP:].mean()
    nis_lagged = lagged.nis[:, SKIP:].mean()
    assert nis_lagged < 8.5 < nis_plain


def test_no_lag_is_learnt_where_there_is_none_and_the_names_are_checked() -> None:
    y = _observations(None)
    cfg = UKFConfig(sensor_lags=("T_rx", "T_dg"))
    out = FCCStateEstimator(fcc_env.FCCParams(), cfg).filter(y, innovation_cov=False)
    assert out.state_names[-2:] == ("lag[T_rx]", "lag[T_dg]")
    assert (out.state("lag_coef[T_rx]")[:, -1] < 0.15).all()
    assert out.nis[:, SKIP:].mean() < 8.5
    with pytest.raises(ValueError, match="sensor_lags"):
        UKFConfig(sensor_lags=("T_fp",))  # an input's channel: no lag state
