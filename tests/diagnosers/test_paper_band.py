"""The paper's band over the whole training record (``band_definition="paper-record"``) and the
reading ``lrgf-mem-paper`` uses."""

from __future__ import annotations

import numpy as np
import pytest

import diagnosers
import fcc_env
from diagnosers import Episode
from diagnosers.lrgf.lrgf_presets import PRESETS, LRGFMEMPaper
from diagnosers.stages.alarm import two_sided_normal_quantile as t_alpha
from diagnosers.stages.band import BandScale, band_scale

# a small model: the oracle checks arithmetic, not the quality of the fit
SMALL = {"max_epochs": 30, "mem_max_epochs": 5, "steady_window": 20}


def _episodes(seeds: list[int], n: int = 600) -> list[Episode]:
    b = fcc_env.simulate_episodes(seeds, n)
    return [
        Episode(b.observations[i].astype(float), fcc_env.MEASUREMENT_NAMES, 10.0, None)
        for i in range(len(seeds))
    ]


@pytest.fixture(scope="module")
def record_band() -> tuple[diagnosers.Diagnoser, list[Episode]]:
    episodes = _episodes([1000, 1001, 1002])
    d = diagnosers.make("lrgf-mem-paper", band_definition="paper-record", **SMALL)
    return d.fit(episodes), episodes


def test_record_band_is_the_std_of_y_e_over_every_training_episode(record_band):
    d, episodes = record_band
    inputs = d.bank_.in_idx[0]
    # oracle: the error model run on each whole episode from its first sample, then numpy
    y_e = np.concatenate([d.bank_.mem[0].predict(e.y[:, inputs])[:, 0] for e in episodes])
    expected = np.std(y_e, ddof=1)
    np.testing.assert_allclose(d.v_, [expected], rtol=1e-12)
    # calibration episodes are in it: not the error model's training part alone
    assert d.v_[0] != pytest.approx(d.bank_.v_paper[0], rel=1e-9)
    # and the band the detector draws is y_m + y_e ± t_α v
    det = d.detect(_episodes([7000], n=300)[0])
    w = d.steady_window
    np.testing.assert_allclose((det.upper[w:] - det.lower[w:]) / 2, t_alpha(0.01) * expected)


def test_record_band_survives_save_and_load(record_band, tmp_path):
    d, _ = record_band
    d.save(tmp_path / "m")
    loaded = diagnosers.Diagnoser.load(tmp_path / "m")
    np.testing.assert_array_equal(loaded.v_, d.v_)
    ep = _episodes([7001], n=300)[0]
    np.testing.assert_array_equal(loaded.detect(ep).alarm, d.detect(ep).alarm)


def test_band_scale_paper_record_is_std_of_what_it_is_given():
    y_e = np.random.default_rng(0).normal(size=(50, 2))
    np.testing.assert_allclose(
        band_scale(y_e, definition="paper-record"), y_e.std(axis=0, ddof=1), rtol=1e-15
    )


def test_the_preset_uses_its_documented_reading():
    reading = PRESETS["lrgf-mem-paper"]["band_definition"]
    assert diagnosers.make("lrgf-mem-paper").get_params()["band_definition"] == reading
    assert reading == BandScale.PAPER_RECORD
    assert f'band_definition="{reading}"' in (LRGFMEMPaper.__doc__ or "")
    # lrgf-mem keeps its own band
    assert diagnosers.make("lrgf-mem").get_params()["band_definition"] == "residual"


def test_a_bad_band_definition_is_refused_by_name():
    allowed = [b.value for b in BandScale]
    with pytest.raises(ValueError, match="papr") as info:
        diagnosers.make("lrgf-mem-paper", band_definition="papr").fit(_episodes([1000], n=300))
    assert all(a in str(info.value) for a in allowed), str(info.value)
    with pytest.raises(ValueError, match="papr") as info:
        band_scale(np.zeros((3, 1)), definition="papr")
    assert all(a in str(info.value) for a in allowed), str(info.value)
