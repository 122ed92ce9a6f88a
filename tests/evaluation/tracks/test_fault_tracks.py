"""The closed-loop fault tracks (issue 43 item 5): ``sensor``, ``actuator``, ``concurrent``.

A track carries a fault as a :class:`FaultTemplate`; the paper-fault tracks' definitions and
store keys must stay byte-identical (their stored results stay valid).
"""

from __future__ import annotations

import hashlib
import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from evaluation.tracks import TRACKS, Fixed, Track, Uniform
from evaluation.tracks.fault_templates import FaultTemplate
from evaluation.tracks.track_data import TrackData
from fcc_env.faults import CONCURRENT_SCENARIO, fault_definition, isolation_outcome
from fcc_env.params import MEASUREMENT_NAMES
from fcc_env.scenarios import FaultSpec

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


def _tiny(name: str, n_templates: int, n_samples: int = 600) -> Track:
    base = TRACKS[name]
    return base.replace(
        n_samples=n_samples,
        onset=Uniform(200, 350),
        n_healthy=2,
        n_faulty=1,
        n_train=2,
        n_validation=1,
        n_train_faults=2,
        fault_templates=base.fault_templates[:n_templates],
        faults=base.faults[:n_templates],
    )


def _check_run(t: Track, records, rows) -> None:
    for fault in t.faults:
        recs = [r for r in records if r.scenario == fault]
        assert recs and {r.fault_onset for r in recs} == {t.fault_spec(fault, 0).onset}
    assert all(set(row.faults) == set(t.faults) for row in rows)


def test_tiny_run_end_to_end(tmp_path: Path):
    """A short sensor track through the sweep (the diagnoser ``limits``), its rows and its
    table: every row has every column, every record its cell's drawn onset."""
    from evaluation.sweep.config import SweepConfig, default_specs
    from evaluation.sweep.runner import run_sweep
    from evaluation.tracks.board_tables import track_table
    from evaluation.tracks.rows import TrackRun, track_rows

    t = _tiny("sensor", 2)
    config = SweepConfig(diagnosers=default_specs(["limits"]), data=TrackData(track=t))
    res = run_sweep(config, tmp_path, n_workers=0, progress=False)
    rows = track_rows(res.records, ["limits"], t.faults)
    _check_run(t, res.records, rows)
    run = TrackRun(
        track=t,
        records=tuple(res.records),
        rows=tuple(rows),
        wall_s=0.0,
        n_computed=res.n_computed,
        n_reused=res.n_reused,
    )
    assert "sensor-drift r_td" in track_table(run)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["sensor", "actuator"])
def test_tiny_run_with_reference_rows(tmp_path: Path, name: str):
    """The same through :func:`run_track`: the six reference rows (about 50 s each).

    The 600-sample ``actuator`` track raised in the directional row before (``no training
    episode of fault valve-bias lasted through its window``: onsets 336 and 328, window 300)."""
    from evaluation.tracks.board import run_track

    t = _tiny(name, 2)
    run = run_track(t, ["limits"], tmp_path, progress=False, figures=False)
    _check_run(t, run.records, run.rows)


def _directional(track: Track):
    from evaluation.tracks.oracle import OracleConfig, PhysicalLimit

    config = OracleConfig(inputs="measured", stage="directional")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no 0/0 direction, no other warning
        return PhysicalLimit(TrackData(track=track), config).fit(seeds=[5000]).stage_


def test_directional_row_skips_a_fault_whose_episodes_end_in_its_window():
    """600 samples: valve-bias's training onsets (336, 328) + the window (300) pass the end,
    valve-stiction's (210, 297) do not. The row keeps valve-stiction's direction and names why
    valve-bias has none, instead of failing the whole row."""
    from evaluation.tracks.oracle import NO_LASTING_EPISODE

    t = _tiny("actuator", 2)
    data = TrackData(track=t)
    onsets = {e.scenario: [] for e in data.train_fault_episodes()}
    for e in data.train_fault_episodes():
        onsets[e.scenario].append(e.fault_onset)
    assert min(onsets["valve-bias"]) + 300 > t.n_samples > max(onsets["valve-stiction"]) + 300
    stage = _directional(t)
    assert stage.faults == ("valve-stiction",)
    assert stage.skipped_ == {"valve-bias": NO_LASTING_EPISODE.format(window=300)}
    assert stage.directions_.shape == (1, len(stage.monitored))
    assert np.isclose(np.linalg.norm(stage.directions_[0]), 1.0)


def test_directional_row_has_no_direction_for_a_noise_fault():
    """Added noise on an uncontrolled channel (T_dg) leaves the noise-free output unchanged:
    its mean signature is exactly zero, so no direction (0/0 before, a RuntimeWarning), and
    the row says why; a bias on the same channel keeps its direction."""
    from evaluation.tracks.oracle import NO_MEAN_SIGNATURE

    base = _tiny("sensor", 1)
    templates = (
        FaultTemplate(scenario="sensor-noise", magnitude=Uniform(2.0, 20.0), channel="T_dg"),
        FaultTemplate(scenario="sensor-bias", magnitude=Uniform(2.0, 10.0), channel="T_dg"),
    )
    t = base.replace(fault_templates=templates, faults=tuple(tp.name for tp in templates))
    stage = _directional(t)
    assert stage.skipped_ == {"sensor-noise": NO_MEAN_SIGNATURE}
    assert stage.faults == ("sensor-bias",)
    assert np.isfinite(stage.directions_).all()


def test_closed_loop_reference_ends_where_the_healthy_model_leaves_its_domain():
    """Actuator seed 5018, valve-stuck: the healthy model driven by the faulty record turns NaN
    at sample 2537 (the faulty plant does not). The reference ends there, the signatures stay
    finite and the optimal CUSUM's limit calibrated on that seed is finite (it was NaN: the
    row never alarmed on the whole track)."""
    from evaluation.tracks.oracle import OracleConfig, PhysicalLimit

    data = TrackData(track=TRACKS["actuator"])
    ep = data.load_test("valve-stuck", 5018).episode
    ref = data.reference(5018, ep.y_clean)
    assert ep.n_samples == 4000 and 2000 < ref.shape[0] < 4000 and np.isfinite(ref).all()
    limit = PhysicalLimit(data, OracleConfig(inputs="true", stage="cusum")).fit(seeds=[5017, 5018])
    assert all(np.isfinite(d).all() for d in limit.stage_.signatures.of(5018))
    assert np.isfinite(limit.stage_.limit_)
    faulty = data.load_test("valve-bias", 5018).episode
    alarm = limit.detect(faulty).alarm
    assert alarm[faulty.fault_onset :].mean() > 0.5  # a 5-20 % valve bias: found at once


def test_known_fault_bank_refuses_a_non_finite_limit():
    from evaluation.tracks.optimal import FaultSignatures, KnownFaultBank

    data = TrackData(track=_tiny("actuator", 1))
    ep = data.simulate([5000], FaultSpec())[0].episode
    bank = KnownFaultBank(
        FaultSignatures(data),
        lambda e: np.full((e.n_samples, 8), np.nan),
        statistic="cusum",
        false_alarm_target=0.01,
    )
    with pytest.raises(ValueError, match="limit is nan"):
        bank.fit([ep])


class _Names:
    """An isolator stand-in that names ``label`` from sample ``start`` on."""

    name = "names"

    def __init__(self, label: str, classes: tuple[str, ...], start: int = 10) -> None:
        self.label, self.classes, self.start = label, classes, start

    def detect(self, ep):
        from diagnosers import Detection

        n = ep.n_samples
        z = np.zeros((n, 1))
        alarm = np.arange(n) >= self.start
        diagnosis = np.where(alarm, self.label, "")
        return Detection(alarm, z, z, z, z, ("x",), diagnosis=diagnosis, class_names=self.classes)


@pytest.mark.parametrize(
    ("said", "outcome"),
    [
        ("sensor-bias+valve-stiction", "correct"),
        ("valve-stiction+sensor-bias", "correct"),  # both names in the other order
        ("sensor-bias", "wrong"),  # one of the two
        ("unknown", "unknown"),
    ],
)
def test_concurrent_isolation_scored_as_isolation_outcome(said: str, outcome: str):
    """A concurrent column's episode is isolated when the diagnosis names both of its faults
    (:meth:`Track.labels`) in any order, as :func:`isolation_outcome` says, whatever order
    the diagnoser's class is named in."""
    from diagnosers.episode.record import Episode
    from evaluation.sweep.records import score_episode
    from evaluation.sweep.sources import LoadedEpisode

    column = "sensor-bias+valve-stiction"
    labels = TRACKS["concurrent"].labels(column)
    assert isolation_outcome(said.split("+"), labels) == outcome or said == "unknown"
    ep = Episode(np.zeros((100, 1)), ("x",), 10.0, 5, column, 0)
    classes = ("valve-stiction+sensor-bias", "sensor-bias", "valve-stiction")
    rec = score_episode(_Names(said, classes), LoadedEpisode(ep, 5, 100, None, None))
    assert rec.cdr == (1.0 if outcome == "correct" else 0.0)
    assert rec.diagnosis == (column if outcome == "correct" else said)
