"""The closed-loop fault tracks (issue 43 item 5): ``sensor``, ``actuator``, ``concurrent``.

A track carries a fault as a :class:`FaultTemplate`; the paper-fault tracks' definitions and
store keys must stay byte-identical (their stored results stay valid).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from evaluation.tracks import TRACKS, Fixed, Track, Uniform
from evaluation.tracks.fault_templates import FaultTemplate
from evaluation.tracks.track_data import TrackData
from fcc_env.faults import CONCURRENT_SCENARIO, fault_definition, isolation_outcome
from fcc_env.params import MEASUREMENT_NAMES

# measured on main at 451af0c, before fault templates existed: (digest, store-key hash)
_BEFORE = {
    "paper": ("42df532383708a17", "1cc0908372b1f1f0"),
    "small": ("6ce2d53974f5e7ca", "884fffc5c87ac779"),
    "incipient": ("d1d2066a0e1f201b", "3a0132150d08f301"),
    "noisy": ("57da448e45d46b17", "6a983e67ff6c771d"),
    "uncertain": ("831a2942e7fa9cab", "550a818caf79639e"),
    "random": ("77925d11feee56b2", "9644715f00064406"),
    "closed": ("50d72a0cd34df2ef", "f4c0274098b5d00a"),
    "closed-random": ("47a1782b7f231b8c", "a6ddfb0229ee589d"),
}
NEW = ("sensor", "actuator", "concurrent")


def _key_hash(track: Track) -> str:
    text = json.dumps(TrackData(track=track).store_key(), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@pytest.mark.parametrize("name", sorted(_BEFORE))
def test_existing_tracks_unchanged(name):
    track = TRACKS[name]
    assert (track.digest()[:16], _key_hash(track)) == _BEFORE[name]
    assert "fault_templates" not in track.to_json()


@pytest.mark.parametrize("name", NEW)
def test_new_tracks_build(name):
    t = TRACKS[name]
    assert t.closed_loop and t.n_healthy >= 200 and t.n_faulty == 20
    assert t.faults == tuple(tp.name for tp in t.fault_templates)
    assert len(t.test_cells()) == t.n_healthy + 20 * len(t.faults)
    assert t.to_json()["fault_templates"][0]["name"] == t.faults[0]


def _check_single(spec, template, track):
    d = fault_definition(spec.scenario)
    assert spec.scenario == template.scenario
    assert template.magnitude.low <= spec.magnitude <= template.magnitude.high
    assert 0.0 <= spec.magnitude <= d.max_magnitude
    onset = template.onset or track.onset
    assert onset.low <= spec.onset <= onset.high <= track.n_samples - 200
    if d.channels:
        allowed = template.channel or (d.default_channel,)
        assert spec.channel in allowed
    else:
        assert spec.channel is None


@pytest.mark.parametrize("name", NEW)
def test_episodes_carry_the_template_spec(name):
    t = TRACKS[name]
    for fault in t.faults:
        tp = t.template(fault)
        channels = set()
        for seed in range(20):
            spec = t.fault_spec(fault, seed)
            assert spec == t.fault_spec(fault, seed)  # deterministic in (track, fault, seed)
            if tp.parts:
                assert spec.scenario == CONCURRENT_SCENARIO
                assert t.labels(fault) == tuple(p.scenario for p in spec.parts)
                for part, ptp in zip(spec.parts, tp.parts, strict=True):
                    _check_single(part, ptp, t)
                assert spec.parts[0].onset < spec.parts[1].onset
            else:
                _check_single(spec, tp, t)
                channels.add(spec.channel)
        if name == "sensor":  # the channel is drawn among the measured ones
            assert len(channels) >= 4 and channels <= set(MEASUREMENT_NAMES)


def test_concurrent_labels_follow_isolation_outcome():
    t = TRACKS["concurrent"]
    labels = t.labels("sensor-bias+valve-stiction")
    assert isolation_outcome(list(reversed(labels)), labels) == "correct"
    assert isolation_outcome(labels[0], labels) == "wrong"
    assert TRACKS["paper"].labels("f1") == ("f1",)


def test_templates_refused_with_reasons():
    with pytest.raises(ValueError, match="magnitude of valve-bias"):
        FaultTemplate(scenario="valve-bias", magnitude=Uniform(0.1, 0.5))
    with pytest.raises(ValueError, match="acts on no measured channel"):
        FaultTemplate(scenario="valve-bias", channel="T_rx")
    with pytest.raises(ValueError, match="channel="):
        FaultTemplate(scenario="sensor-bias", channel="u_F")
    bias = FaultTemplate(scenario="sensor-bias")
    with pytest.raises(ValueError, match="two different faults"):
        FaultTemplate(scenario="concurrent", parts=(bias, bias))
    with pytest.raises(ValueError, match="each part carries its own"):
        FaultTemplate(
            scenario="concurrent", parts=(bias, FaultTemplate(scenario="f1")), onset=Fixed(100)
        )
    with pytest.raises(ValueError, match="closed_loop"):
        Track(name="x", description="x", fault_templates=(FaultTemplate(scenario="valve-stuck"),))
    with pytest.raises(ValueError, match="magnitudes"):
        Track(name="x", description="x", fault_templates=(bias,), magnitudes={"f1": Fixed(0.1)})
    with pytest.raises(ValueError, match="onset"):
        Track(name="x", description="x", fault_templates=(bias,), onset=Uniform(1000, 3900))


def test_open_loop_template_track_defaults():
    t = Track(name="x", description="x", fault_templates=(FaultTemplate(scenario="f2"),))
    spec = t.fault_spec("f2", 0)
    assert (spec.scenario, spec.magnitude, spec.onset) == ("f2", 0.15, 1900)


def test_tiny_run_end_to_end(tmp_path: Path):
    """A short sensor track, one healthy and one faulty episode per fault, through the sweep
    (the diagnoser ``limits``) and the reference rows: every row has every column."""
    from evaluation.tracks.board import run_track

    base = TRACKS["sensor"]
    t = base.replace(
        n_samples=600,
        onset=Uniform(200, 350),
        n_healthy=1,
        n_faulty=1,
        n_train=2,
        n_validation=1,
        n_train_faults=2,
        fault_templates=base.fault_templates[:2],
        faults=base.faults[:2],
    )
    run = run_track(t, ["limits"], tmp_path, progress=False, figures=False)
    for fault in t.faults:
        recs = [r for r in run.records if r.scenario == fault]
        assert recs and all(r.fault_onset is not None for r in recs)
        spec = t.fault_spec(fault, 0)
        assert {r.fault_onset for r in recs} == {spec.onset}
    assert all(set(row.faults) == set(t.faults) for row in run.rows)
