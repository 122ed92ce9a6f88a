"""Tests of evaluation.tracks: validation, deterministic fault specs, cells, serialisation."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import fcc_env
from evaluation.tracks import (
    MIN_HEALTHY,
    RAMP_LENGTHS,
    RAMP_MARGIN,
    TRACKS,
    Choice,
    Fixed,
    Track,
    Uniform,
    parse_tracks,
    stable_hash,
    tracks_markdown,
)
from fcc_env.scenarios import FAULTS, PAPER_FAULTS, FaultProfile, FaultSpec

PAPER_MAG = {f: FAULTS[f].default_magnitude for f in PAPER_FAULTS}
PAPER_ONSET = {f: FAULTS[f].default_onset for f in PAPER_FAULTS}


def faulty_cells(track: Track) -> list[tuple[str, int]]:
    return [c for c in track.test_cells() if c[0] != "nominal"]


# ---- the published tracks ----------------------------------------------------------------------
def test_published_tracks() -> None:
    assert set(TRACKS) >= {"paper", "small", "incipient", "noisy", "uncertain", "random"}
    for name, t in TRACKS.items():
        assert t.name == name
        assert t.n_healthy >= MIN_HEALTHY
        assert len(t.description) > 80
    assert TRACKS["noisy"].noise_scale == 2.0
    assert TRACKS["uncertain"].plant_variation
    assert not TRACKS["paper"].plant_variation and TRACKS["paper"].noise_scale == 1.0


def test_paper_track_is_todays_leaderboard() -> None:
    t = TRACKS["paper"]
    cells = t.test_cells()
    assert cells[:50] == [("nominal", s) for s in range(50)]
    for f in PAPER_FAULTS:
        assert [s for sc, s in cells if sc == f] == list(range(20))
        spec = t.fault_spec(f, 7)
        assert spec == FaultSpec(
            scenario=f, onset=PAPER_ONSET[f], magnitude=PAPER_MAG[f], profile=FaultProfile.ABRUPT
        )


def test_small_track_magnitudes() -> None:
    t = TRACKS["small"]
    mags = {f: t.fault_spec(f, 0).magnitude for f in PAPER_FAULTS}
    assert mags == {"f1": 0.005, "f2": 0.03, "f3": 0.012, "f4": 0.01}
    assert all(t.fault_spec(f, 0).onset == PAPER_ONSET[f] for f in PAPER_FAULTS)


def test_every_cell_resolves_in_the_env_horizon() -> None:
    for t in TRACKS.values():
        for sc, seed in t.test_cells():
            cfg = t.fault_spec(sc, seed).resolve(horizon=t.n_samples)
            # a concurrent column (a+b) resolves to its two faults
            assert cfg.scenario == sc if sc == "nominal" else cfg.labels == t.labels(sc)


# ---- determinism -------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["incipient", "random"])
def test_fault_spec_deterministic_and_order_independent(name: str) -> None:
    t = TRACKS[name]
    cells = faulty_cells(t)
    forward = [t.fault_spec(sc, s) for sc, s in cells]
    backward = [t.fault_spec(sc, s) for sc, s in reversed(cells)][::-1]
    assert forward == backward
    rebuilt = dataclasses.replace(t)  # a fresh object: no hidden state carried
    assert [rebuilt.fault_spec(sc, s) for sc, s in cells] == forward


def test_fault_spec_differs_across_seeds_and_tracks() -> None:
    t = TRACKS["incipient"]
    specs = {(s.onset, s.ramp_samples) for s in (t.fault_spec("f1", seed) for seed in range(20))}
    assert len(specs) > 10
    other = t.replace(name="incipient-copy")
    assert [other.fault_spec("f1", s) for s in range(20)] != [
        t.fault_spec("f1", s) for s in range(20)
    ]


def test_fault_spec_leaves_global_rng_alone() -> None:
    np.random.seed(5)
    before = np.random.get_state()[1].copy()
    TRACKS["random"].fault_spec("f2", 3)
    TRACKS["random"].test_cells()
    assert np.array_equal(np.random.get_state()[1], before)


def test_stable_hash_is_crc32() -> None:
    assert stable_hash("random") == stable_hash("random")
    assert stable_hash("f1") != stable_hash("f2")
    assert 0 <= stable_hash("paper") < 2**32


def test_nominal_spec() -> None:
    assert TRACKS["random"].fault_spec("nominal", 4) == FaultSpec(scenario="nominal")


# ---- incipient and random ----------------------------------------------------------------------
def test_incipient_ramps_fit_in_the_horizon() -> None:
    t = TRACKS["incipient"]
    ramps = set()
    for sc, s in faulty_cells(t):
        spec = t.fault_spec(sc, s)
        assert spec.profile is FaultProfile.INCIPIENT
        assert 1000 <= spec.onset <= 1500
        assert spec.onset + spec.ramp_samples <= t.n_samples - RAMP_MARGIN
        assert spec.magnitude == PAPER_MAG[sc]
        ramps.add(spec.ramp_samples)
    assert ramps == set(RAMP_LENGTHS)


@settings(max_examples=60, deadline=None)
@given(
    st.sampled_from(["incipient", "random"]), st.sampled_from(PAPER_FAULTS), st.integers(0, 10**6)
)
def test_any_seed_gives_a_ramp_that_completes(name: str, fault: str, seed: int) -> None:
    t = TRACKS[name]
    spec = t.fault_spec(fault, seed)
    end = spec.onset + (spec.ramp_samples or 0)
    assert 1 <= spec.onset and end <= t.n_samples - RAMP_MARGIN
    assert spec == t.fault_spec(fault, seed)


def test_random_track_cells_name_true_faults_and_draw_all_fields() -> None:
    t = TRACKS["random"]
    cells = faulty_cells(t)
    assert len(cells) == t.n_faulty * len(PAPER_FAULTS)
    assert [s for _, s in cells] == list(range(len(cells)))
    seen_faults, seen_profiles, onsets, scales = set(), set(), set(), set()
    for sc, s in cells:
        assert sc == t.drawn_fault(s)
        spec = t.fault_spec(sc, s)
        assert spec.scenario == sc
        assert spec.resolve(horizon=t.n_samples).scenario == sc
        scale = spec.magnitude / PAPER_MAG[sc]
        assert 0.3 - 1e-12 <= scale <= 1.3 + 1e-12
        assert 1000 <= spec.onset <= 3000
        seen_faults.add(sc)
        seen_profiles.add(spec.profile)
        onsets.add(spec.onset)
        scales.add(round(scale, 6))
    assert seen_faults == set(PAPER_FAULTS)
    assert seen_profiles == set(FaultProfile)
    assert len(onsets) > 40 and len(scales) > 40


# ---- validation --------------------------------------------------------------------------------
def make(**changes: object) -> Track:
    return Track(**{"name": "t", "description": "a test track", **changes})  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"name": "Bad Name"}, r"name='Bad Name' is outside the allowed range: a lowercase name"),
        ({"description": " "}, r"description=' ' is outside the allowed range: a non-empty string"),
        (
            {"faults": ("f1", "f5")},
            r"faults='f5' is outside the allowed range: one of \['f1', 'f2', 'f3', 'f4'\]",
        ),
        ({"faults": ("f1", "f1")}, r"faults=\('f1', 'f1'\) is outside the allowed range: distinct"),
        (
            {"noise_scale": -1},
            r"noise_scale=-1 is outside the allowed range: a number in \(0, 100\]",
        ),
        ({"n_healthy": 0}, r"n_healthy=0 is outside the allowed range: an integer in \[1, inf\)"),
        ({"plant_variation": 1}, r"plant_variation=1 is outside the allowed range: True or False"),
        (
            {"profiles": ("sudden",)},
            r"profiles='sudden' is outside the allowed range: one of \['abrupt', 'incipient'\]",
        ),
        (
            {
                "magnitudes": {
                    "f1": Fixed(0.95),
                    "f2": Fixed(0.1),
                    "f3": Fixed(0.1),
                    "f4": Fixed(0.1),
                }
            },
            r"magnitudes\['f1'\]=Fixed\(value=0\.95\) is outside the allowed range: "
            r"a distribution with support in \[0, 0\.9\]",
        ),
        (
            {"magnitudes": {"f1": Fixed(0.1)}},
            r"magnitudes=\['f1'\] is outside the allowed range: one distribution for each fault "
            r"of the track \['f1', 'f2', 'f3', 'f4'\]",
        ),
        (
            {"onset": Uniform(10, 3900)},
            r"onset=Uniform\(low=10\.0, high=3900\.0\) is outside the allowed range: "
            r"a distribution with support in \[1, 3800\]",
        ),
        (
            {"closed_loop": True, "plant_variation": True},
            r"plant_variation=True is outside the allowed range: False on a closed-loop track",
        ),
        ({"closed_loop": "yes"}, r"closed_loop='yes' is outside the allowed range"),
        (
            {"ramp": Fixed(500)},
            r"ramp=Fixed\(value=500\) is outside the allowed range: None \(a ramp needs 'incipient'",
        ),
        (
            {
                "profiles": (FaultProfile.INCIPIENT,),
                "onset": Uniform(1000, 3000),
                "ramp": Fixed(1000),
            },
            r"ramp=Fixed\(value=1000\) is outside the allowed range: a length <= 800 samples",
        ),
    ],
)
def test_bad_values_rejected_with_value_and_allowed_range(changes: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        make(**changes)


def test_overlapping_seed_ranges_name_the_overlap() -> None:
    with pytest.raises(
        ValueError,
        match=r"train_seed_start=190 is outside the allowed range: a start whose seeds 190\.\.209 "
        r"avoid the test seeds 0\.\.199 \(seeds 190\.\.199 would be both test and train seeds\)",
    ):
        make(train_seed_start=190)
    with pytest.raises(ValueError, match=r"seeds 5000\.\.5019 would be both test and validation"):
        make(test_seed_start=4990)


def test_with_seeds_holds_out_a_private_range() -> None:
    t = TRACKS["paper"].with_seeds(test=100_000)
    assert t.test_cells()[0] == ("nominal", 100_000)
    assert t.test_seeds == range(100_000, 100_000 + MIN_HEALTHY)
    assert t.train_seeds == TRACKS["paper"].train_seeds
    assert t.digest() != TRACKS["paper"].digest()


def test_distributions_validated() -> None:
    with pytest.raises(
        ValueError,
        match=r"high=1 is outside the allowed range: a number in \[2, inf\) \(high >= low\)",
    ):
        Uniform(2, 1)
    with pytest.raises(
        ValueError, match=r"values=\(\) is outside the allowed range: a non-empty tuple"
    ):
        Choice(())
    with pytest.raises(ValueError, match=r"value='x' is outside the allowed range"):
        Fixed("x")  # type: ignore[arg-type]


def test_random_ramp_is_restricted_to_lengths_that_fit() -> None:
    # onset 3000 leaves 800 samples: only the 500-sample ramp completes in time
    t = make(
        profiles=(FaultProfile.INCIPIENT,),
        onset=Fixed(3000),
        ramp=Choice(RAMP_LENGTHS),
    )
    assert {t.fault_spec("f1", s).ramp_samples for s in range(30)} == {500}


# ---- CLI parsing and serialisation -------------------------------------------------------------
def test_parse_tracks() -> None:
    assert [t.name for t in parse_tracks("paper,small")] == ["paper", "small"]
    assert [t.name for t in parse_tracks(" noisy , paper, noisy")] == ["noisy", "paper"]
    assert parse_tracks("all") == tuple(TRACKS.values())
    allowed = (
        r"one of \['actuator', 'closed', 'closed-random', 'concurrent', 'incipient', 'mismatch', "
        r"'noisy', 'paper', 'random', 'regimes', 'sensor', 'small', 'uncertain', 'all'\]"
    )
    with pytest.raises(ValueError, match=rf"track='bogus' is outside the allowed range: {allowed}"):
        parse_tracks("paper,bogus")
    with pytest.raises(ValueError, match=rf"track='' is outside the allowed range: {allowed}"):
        parse_tracks("paper,")
    with pytest.raises(ValueError, match=r"tracks='paper,all' is outside the allowed range"):
        parse_tracks("paper,all")


def test_to_json_is_json_and_changes_with_the_track() -> None:
    for t in TRACKS.values():
        obj = t.to_json()
        assert json.loads(json.dumps(obj)) == obj
        assert hash(t) == hash(dataclasses.replace(t))
    digests = {t.digest() for t in TRACKS.values()}
    assert len(digests) == len(TRACKS)
    t = TRACKS["small"]
    assert t.digest() == dataclasses.replace(t).digest()
    assert t.replace(n_faulty=21).digest() != t.digest()
    assert t.replace(magnitudes={**dict(t.magnitudes), "f1": Fixed(0.03)}).digest() != t.digest()
    assert TRACKS["random"].to_json()["magnitudes"]["f2"] == {
        "kind": "uniform",
        "low": pytest.approx(0.045),
        "high": pytest.approx(0.195),
    }


def test_tracks_markdown_lists_every_track() -> None:
    text = tracks_markdown()
    for t in TRACKS.values():
        assert f"| `{t.name}` |" in text and t.description in text


def test_lrgf_glr_default_fault_seeds_are_the_tracks_first_training_seeds() -> None:
    # diagnosers cannot import the tracks: the default is written there, and pinned here
    from diagnosers.lrgf.fault_directions import DEFAULT_FAULT_SEEDS
    from evaluation.tracks import TRAIN_SEED_START

    assert DEFAULT_FAULT_SEEDS == tuple(range(TRAIN_SEED_START, TRAIN_SEED_START + 3))
    for track in TRACKS.values():  # each has its healthy twin among the training episodes
        assert set(DEFAULT_FAULT_SEEDS) <= set(track.train_seeds) & set(track.train_fault_seeds)


def test_a_mismatch_track_draws_undeclared_effects_on_the_declared_plant() -> None:
    t = TRACKS["mismatch"]
    draw = t.plant_draw.draw(5000)  # type: ignore[union-attr]
    assert draw.params == fcc_env.FCCParams()  # nothing declared changes
    kinds = sorted({e.kind for e in draw.effects})
    assert kinds == ["catalyst_deactivation", "heat_loss", "sensor_lag"]
    assert draw == t.plant_draw.draw(5000) != t.plant_draw.draw(5001)  # type: ignore[union-attr]
    assert (
        t.to_json()["plant_mismatch"] is True and "plant_mismatch" not in TRACKS["paper"].to_json()
    )
    with pytest.raises(ValueError, match="plant_mismatch"):
        t.replace(plant_variation=True)
