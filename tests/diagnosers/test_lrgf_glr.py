"""The sequential tests of the alarm stage against hand-computed oracles, and ``lrgf-glr``'s
cross-fitted calibration and its detectors' stream == batch."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal, stats
from synthetic import inject_step_fault, make_episode, with_fault_twins

import diagnosers
from diagnosers.bank.relation_bank import RelationBank
from diagnosers.lrgf.lrgf_glr import LRGFGLR
from diagnosers.stages.alarm import CUSUM, DirectionalGLR, DirectionalProjection, normal_tail_limit


def _cusum_oracle(x: np.ndarray, drift: float) -> np.ndarray:
    out, g = [], 0.0
    for v in x:
        g = max(0.0, g + v - drift)
        out.append(g)
    return np.array(out)


def _glr_oracle(x: np.ndarray, window: int) -> np.ndarray:
    out = []
    for k in range(len(x)):
        best = 0.0
        for n in range(1, min(window, k + 1) + 1):
            s = float(np.sum(x[k - n + 1 : k + 1]))
            best = max(best, max(0.0, s) ** 2 / n)
        out.append(best)
    return np.array(out)


def test_cusum_matches_hand_recursion_stream_and_batch() -> None:
    x = np.random.default_rng(0).normal(0.3, 1.0, size=(300, 2))
    c = CUSUM(0.5)
    batch = c.filter(x)
    for j in range(2):
        np.testing.assert_allclose(batch[:, j], _cusum_oracle(x[:, j], 0.5), rtol=0, atol=1e-12)
    c.reset()
    stream = np.array([c.update(row).copy() for row in x])
    np.testing.assert_array_equal(stream, batch)


def test_cusum_hand_values() -> None:
    # 1 - .5 = .5; .5 + 1 - .5 = 1; max(0, 1 - 2 - .5) = 0; 0 + 3 - .5 = 2.5
    assert CUSUM(0.5).filter(np.array([[1.0], [1.0], [-2.0], [3.0]]))[:, 0].tolist() == [
        0.5,
        1.0,
        0.0,
        2.5,
    ]
    with pytest.raises(ValueError, match="drift"):
        CUSUM(-1.0)


@pytest.mark.parametrize("window", [1, 3, 17, 400])
def test_glr_matches_brute_force_stream_and_batch(window: int) -> None:
    x = np.random.default_rng(window).normal(0.2, 1.0, size=(120, 3))
    g = DirectionalGLR(window)
    batch = g.filter(x)
    for j in range(3):
        np.testing.assert_allclose(batch[:, j], _glr_oracle(x[:, j], window), rtol=1e-12)
    g.reset()
    stream = np.array([g.update(row).copy() for row in x])
    np.testing.assert_allclose(stream, batch, rtol=1e-12, atol=1e-12)


def test_glr_hand_values() -> None:
    # k=0: 1²/1; k=1: max(3²/1, (1+3)²/2) = 9; k=2: max(0, (3-5)→0, ...) = 0 with window 2
    assert DirectionalGLR(2).filter(np.array([[1.0], [3.0], [-5.0]]))[:, 0].tolist() == [
        1.0,
        9.0,
        0.0,
    ]
    # a step of size mu after a long healthy stretch: the statistic grows like n mu²
    x = np.r_[np.zeros(50), np.full(20, 0.5)][:, None]
    assert DirectionalGLR(100).filter(x)[-1, 0] == pytest.approx(20 * 0.25)


def test_directional_projection_is_the_standardised_matched_filter() -> None:
    rng = np.random.default_rng(1)
    cov = np.array([[2.0, 0.8], [0.8, 1.0]])
    X = rng.multivariate_normal([0, 0], cov, size=200_000)
    d = np.array([[1.0, -1.0], [0.0, 1.0]])
    proj = DirectionalProjection().fit(d, cov)
    p = proj.score(X)
    np.testing.assert_allclose(p.std(axis=0), 1.0, atol=0.01)  # unit variance when healthy
    # a shift mu*d moves score i by mu*sqrt(d_i' S^-1 d_i): the Mahalanobis length of d_i
    prec = np.linalg.inv(cov)
    for i in range(2):
        shift = proj.score(3.0 * d[i])[i]
        assert shift == pytest.approx(3.0 * np.sqrt(d[i] @ prec @ d[i]))
    proj2 = DirectionalProjection()
    proj2.set_state(proj.get_state())
    np.testing.assert_array_equal(proj2.score(X[:5]), proj.score(X[:5]))
    with pytest.raises(ValueError, match="non-zero"):
        DirectionalProjection().fit(np.zeros((1, 2)), cov)


def test_normal_tail_limit_normal_and_heavy_tail() -> None:
    rng = np.random.default_rng(2)
    x = rng.standard_normal((400_000, 1))
    assert normal_tail_limit(x, 0.002)[0] == pytest.approx(stats.norm.ppf(0.998), rel=0.02)
    heavy = rng.standard_t(3, size=(400_000, 1))
    sd = np.sqrt(np.mean(heavy**2))
    # inflated above the plain normal reference, never below it
    assert normal_tail_limit(heavy, 0.002)[0] > sd * stats.norm.ppf(0.998)


# ---- lrgf-glr ------------------------------------------------------------------------------------
FAST = {**LRGFGLR.fast_params(), "fault_scenarios": ["f3"], "fault_seeds": None}


@pytest.fixture(scope="module")
def train(train) -> list[diagnosers.Episode]:
    """The healthy training episodes and their f3-labelled noise twins (the direction's data)."""
    return with_fault_twins(train)


def test_cross_fit_calibrates_on_out_of_fold_residuals(train, monkeypatch) -> None:
    calls: list[list[list[int]]] = []
    banks: list = []
    real = LRGFGLR._train_banks

    def spy(self, sets, init=None, max_epochs=None):
        calls.append([[next(i for i, e in enumerate(train) if e.y is r) for r in s] for s in sets])
        out = real(self, sets, init=init, max_epochs=max_epochs)
        banks.extend(out)
        return out

    monkeypatch.setattr(LRGFGLR, "_train_banks", spy)
    parts: list[tuple[int, int]] = []
    real_parts = RelationBank.parts

    def spy_parts(self, y):
        hit = [i for i, e in enumerate(train) if e.y is y]
        if hit:
            bank = next(b for b, bank in enumerate(banks) if bank.lrgf[0] is self.lrgf[0])
            parts.append((hit[0], bank))
        return real_parts(self, y)

    monkeypatch.setattr(RelationBank, "parts", spy_parts)
    det = LRGFGLR(**{**FAST, "n_folds": 3}).fit(train)
    # one bank per fold without that fold's episodes, then the final bank on all of them, all
    # trained in one call (so that n_jobs processes share every job)
    assert calls == [[[1, 2], [0, 2], [0, 1], [0, 1, 2]]]
    # each episode's out-of-fold calibration residual comes from the bank that never saw it
    assert sorted(parts) == [(0, 0), (1, 1), (2, 2)]
    assert det.lrgf_[0] is banks[3].lrgf[0]  # the detector keeps the bank trained on all
    assert det.stage_.h_.shape == (1,) and det.stage_.h_dir_.shape == (
        2,
    )  # f3 on the fast and slow scale


def test_holdout_calibration_is_lrgf_mem_split(train, monkeypatch) -> None:
    calls: list[list[int]] = []
    real = LRGFGLR._train_banks
    monkeypatch.setattr(
        LRGFGLR,
        "_train_banks",
        lambda self, s, **kw: (calls.append([len(r) for r in s]), real(self, s, **kw))[1],
    )
    LRGFGLR(**{**FAST, "calibration": "holdout"}).fit(train)
    assert calls == [[2]]  # trained once, on the first two thirds


def _stream_equals_batch(det: LRGFGLR, ep) -> diagnosers.Detection:
    """Assert streaming ``update`` reproduces batch ``detect``; return the batch detection."""
    batch = det.detect(ep)
    det.reset()
    stream = [det.update(row) for row in ep.y]
    np.testing.assert_array_equal(batch.alarm, [d.alarm for d in stream])
    np.testing.assert_allclose(batch.signal, [d.signal for d in stream], rtol=1e-9, atol=1e-9)
    return batch


@pytest.mark.parametrize("statistic", ["t2", "directional", "glr", "cusum"])
def test_statistics_stream_equals_batch_and_roundtrip(train, statistic, tmp_path) -> None:
    det = LRGFGLR(**{**FAST, "n_folds": 2, "statistic": statistic, "glr_window": 30}).fit(train)
    ep = inject_step_fault(make_episode(900, seed=9), onset=500, magnitude=3.0)
    batch = _stream_equals_batch(det, ep)
    # one test per direction (f3), two for the directional detector: its fast and slow scale
    n_dir = {"t2": 0, "directional": 2}.get(statistic, 1)
    assert batch.signal.shape == (900, 1 + n_dir)
    assert not batch.alarm[: det.steady_window].any()
    det.save(tmp_path / "m")
    again = diagnosers.Diagnoser.load(tmp_path / "m").detect(ep)
    np.testing.assert_array_equal(again.alarm, batch.alarm)


def test_directions_are_unit_vectors_of_the_labelled_faults(train) -> None:
    det = LRGFGLR(**FAST).fit(train)
    assert det.directions_.shape == (1, 3)  # f3 over the three relations
    np.testing.assert_allclose(np.linalg.norm(det.directions_, axis=1), 1.0)
    assert det.direction_faults_ == ("f3",) and det.signal_names_[1] == "directional[f3]"
    # the signature is the faulty episode's normalised error minus its noise twin's
    f3 = [e for e in train if e.fault_onset is not None]
    twin = {e.seed: e for e in train if e.fault_onset is None}
    d = [
        (det.normalised(e.y[:900]) - det.normalised(twin[e.seed].y[:900]))[600:].mean(axis=0)
        for e in f3
    ]
    mean = np.mean(d, axis=0)
    np.testing.assert_allclose(det.directions_[0], mean / np.linalg.norm(mean), rtol=1e-12)
    # refused before anything trains (default, slow hyperparameters)
    with pytest.raises(ValueError, match=r"fault_seeds=\[5000\]"):
        LRGFGLR(fault_scenarios=["f3"], fault_seeds=[5000]).fit(train)
    with pytest.raises(ValueError, match="fault_scenarios names 'f9'"):
        LRGFGLR(fault_scenarios=["f9"]).fit(train)
    with pytest.raises(ValueError, match="no healthy episode of that seed"):
        LRGFGLR(fault_seeds=None).fit(train[1:])  # seed 1's twin left out


@pytest.mark.parametrize("labelled", [False, True])
def test_without_usable_faults_no_directions_and_a_warning(train, caplog, labelled) -> None:
    # none passed, or (every fault passed asked for) none on fault_seeds: the T² alone
    given = train if labelled else [e for e in train if e.fault_onset is None]
    params = {**FAST, "fault_scenarios": None, "fault_seeds": [1000], "n_folds": 2}
    with caplog.at_level("WARNING", logger="diagnosers.lrgf.fault_directions"):
        det = LRGFGLR(**params).fit(given)
    said = "is on fault_seeds=[1000]" if labelled else "no labelled faulty training episode"
    assert said in caplog.text
    assert det.directions_.shape == (0, 3) and det.signal_names_ == ("T2[ewma]",)


def test_direction_names_are_saved_with_the_model(train, tmp_path) -> None:
    faults = with_fault_twins(
        [e for e in train if e.fault_onset is None], "g7", steps={"T_rg2": 2.0}
    )
    det = LRGFGLR(**{**FAST, "fault_scenarios": None, "n_folds": 2}).fit(faults)
    det.save(tmp_path / "m")
    loaded = diagnosers.Diagnoser.load(tmp_path / "m")
    assert loaded.direction_faults_ == ("g7",) and loaded.signal_names_ == det.signal_names_
    # a model saved before the names were saved learned the faults its parameters named
    state_file = tmp_path / "m" / "state.npz"
    with np.load(state_file) as npz:
        state = {k: npz[k] for k in npz.files if k != "direction_faults"}
    np.savez(state_file, **state)
    assert diagnosers.Diagnoser.load(tmp_path / "m").signal_names_[1] == "directional[f1]"


# ---- the held baseline ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def baseline_det(train) -> LRGFGLR:
    # lrgf-glr-adaptive's stage: the baseline without the slow scale (which would integrate the
    # settling transient of the baseline for a few of its time constants); the target these
    # tests' offsets were sized for, whatever the class default is
    params = {
        **FAST,
        "n_folds": 2,
        "baseline_lambda": 0.02,
        "baseline_settle": 50,
        "false_alarm_target": 0.03,
    }
    return LRGFGLR(**params, slow_ewma_lambda=0.0).fit(train)


@pytest.mark.parametrize("statistic", ["directional", "cusum"])
def test_baseline_stream_equals_batch_and_roundtrip(baseline_det, statistic, tmp_path) -> None:
    det = baseline_det
    if statistic != det.statistic:
        det = LRGFGLR(**{**det.get_params(), "statistic": statistic})
        det.fit(with_fault_twins([make_episode(1500, seed=s) for s in (1, 2, 3)]))
    ep = inject_step_fault(make_episode(900, seed=9), onset=500, magnitude=3.0)
    batch = _stream_equals_batch(det, ep)
    det.save(tmp_path / "m")
    again = diagnosers.Diagnoser.load(tmp_path / "m")
    assert again.baseline_lambda == 0.02 and again.baseline_settle == 50
    np.testing.assert_array_equal(again.detect(ep).alarm, batch.alarm)


def _offset(ep, column: str, value: float, onset: int = 0):
    y = ep.y.copy()
    y[onset:, ep.channels.index(column)] += value
    return diagnosers.Episode(y, ep.channels, ep.sample_time_s, fault_onset=ep.fault_onset)


def test_baseline_absorbs_an_offset_present_from_the_start(baseline_det) -> None:
    # a plant that sits 4 residual scales off the model from the start (another unit, another
    # catalyst): without the baseline the detector alarms throughout, with it only while settling
    col = baseline_det.channels_[baseline_det.out_idx_[1]]
    ep = _offset(make_episode(1500, seed=11), col, 4.0 * baseline_det.v_residual_[1])
    w = baseline_det.steady_window + baseline_det.baseline_settle
    with_baseline = baseline_det.detect(ep).alarm[w:]
    plain = LRGFGLR(**{**baseline_det.get_params(), "baseline_lambda": 0.0})
    plain.fit(with_fault_twins([make_episode(1500, seed=s) for s in (1, 2, 3)]))
    without = plain.detect(ep).alarm[w:]
    assert without.mean() > 0.9
    assert with_baseline.mean() < 0.05


def test_baseline_holds_on_a_fault(baseline_det) -> None:
    # a step that appears later is not absorbed: the baseline holds while the statistic is high,
    # so the alarm lasts as long as the fault
    col = baseline_det.channels_[baseline_det.out_idx_[1]]
    ep = _offset(make_episode(1500, seed=12), col, 8.0 * baseline_det.v_residual_[1], onset=800)
    alarm = baseline_det.detect(ep).alarm
    assert alarm[800:810].any()
    assert alarm[820:].mean() > 0.95


@pytest.mark.parametrize(
    ("name", "value"),
    [("baseline_lambda", 1.0), ("baseline_lambda", -0.1), ("baseline_hold", 0.0),
     ("baseline_settle", -1)],
)  # fmt: skip
def test_baseline_parameters_are_checked(train, name, value) -> None:
    with pytest.raises(ValueError, match=f"{name}={value}"):
        LRGFGLR(**{**FAST, name: value}).fit(train)


# ---- the slow EWMA scale -------------------------------------------------------------------------
@pytest.fixture(scope="module")
def slow_det(train) -> LRGFGLR:
    return LRGFGLR(**{**FAST, "n_folds": 2, "slow_ewma_lambda": 0.03}).fit(train)


@pytest.mark.parametrize("baseline_lambda", [0.0, 0.02])
def test_slow_scale_stream_equals_batch_and_roundtrip(
    slow_det, train, baseline_lambda, tmp_path
) -> None:
    det = slow_det
    if baseline_lambda:
        det = LRGFGLR(**{**det.get_params(), "baseline_lambda": baseline_lambda}).fit(train)
    ep = inject_step_fault(make_episode(900, seed=9), onset=500, magnitude=3.0)
    batch = _stream_equals_batch(det, ep)
    # T², then the fast and the slow projection on the one learned direction (f3)
    assert batch.signal.shape == (900, 3)
    assert det.signal_names_ == ("T2[ewma]", "directional[f3]", "directional-slow[f3]")
    assert det.stage_.dir_weights_.shape == (2, 6)  # block-diagonal over [fast EWMA, slow EWMA]
    np.testing.assert_array_equal(det.stage_.dir_weights_[0, 3:], 0.0)
    np.testing.assert_array_equal(det.stage_.dir_weights_[1, :3], 0.0)
    det.save(tmp_path / "m")
    again = diagnosers.Diagnoser.load(tmp_path / "m")
    assert again.slow_ewma_lambda == 0.03
    np.testing.assert_array_equal(again.detect(ep).signal, batch.signal)


def test_slow_scale_limits_hold_the_split_target(slow_det, train) -> None:
    # the slow scale takes half of the directional target and none of the omnibus T²'s: the T²
    # limit is the plain detector's, the fast projection's is the plain one's at half the target
    params = {**slow_det.get_params(), "slow_ewma_lambda": 0.0}
    plain = LRGFGLR(**params).fit(train)
    half = LRGFGLR(**{**params, "false_alarm_target": params["false_alarm_target"] / 2}).fit(train)
    assert slow_det.stage_.h_ == pytest.approx(plain.stage_.h_)
    assert slow_det.stage_.h_dir_[0] == pytest.approx(half.stage_.h_dir_[0])
    assert slow_det.stage_.h_dir_[0] > plain.stage_.h_dir_[0]


def test_slow_score_is_the_projected_slow_ewma(slow_det) -> None:
    # oracle: the slow EWMA as scipy's first-order filter of the normalised remaining error
    # (zero through the warm-up), projected on the slow block's weights
    ep = inject_step_fault(make_episode(900, seed=9), onset=500, magnitude=1.0)
    norm = slow_det.normalised(ep.y)
    norm[: slow_det.steady_window] = 0.0
    lam = slow_det.slow_ewma_lambda
    z_slow = signal.lfilter([lam], [1.0, lam - 1.0], norm, axis=0)
    k = len(slow_det.out_idx_)
    expected = z_slow @ slow_det.stage_.dir_weights_[1, k:]
    got = slow_det.detect(ep).signal[:, 2]
    w = slow_det.steady_window
    np.testing.assert_allclose(got[w:], expected[w:], rtol=1e-9, atol=1e-9)


def test_slow_scale_parameters_are_checked(train) -> None:
    with pytest.raises(ValueError, match=r"slow_ewma_lambda=1\.0"):
        LRGFGLR(**{**FAST, "slow_ewma_lambda": 1.0}).fit(train)
    with pytest.raises(
        ValueError, match=r"slow_share=1.0 is outside the allowed range: .*\(0, 1\)"
    ):
        LRGFGLR(**{**FAST, "slow_ewma_lambda": 0.03, "slow_share": 1.0}).fit(train)


# ---- several slow scales ---------------------------------------------------------------------------
def test_several_slow_scales_stream_equal_batch_and_roundtrip(slow_det, train, tmp_path) -> None:
    params = {**slow_det.get_params(), "slow_ewma_lambda": [0.1, 0.03]}
    det = LRGFGLR(**params).fit(train)
    ep = inject_step_fault(make_episode(900, seed=9), onset=500, magnitude=1.0)
    batch = _stream_equals_batch(det, ep)
    assert det.signal_names_ == (
        "T2[ewma]", "directional[f3]", "directional-slow1[f3]", "directional-slow2[f3]"
    )  # fmt: skip
    assert det.stage_.dir_weights_.shape == (3, 9)  # block-diagonal over [fast, λ 0.1, λ 0.03]
    # oracle: each slow score is scipy's first-order filter of the normalised remaining error,
    # projected on its block's weights
    norm = det.normalised(ep.y)
    w, k = det.steady_window, len(det.out_idx_)
    norm[:w] = 0.0
    for j, lam in enumerate((0.1, 0.03), start=1):
        z = signal.lfilter([lam], [1.0, lam - 1.0], norm, axis=0)
        expected = z @ det.stage_.dir_weights_[j, j * k : (j + 1) * k]
        np.testing.assert_allclose(batch.signal[w:, 1 + j], expected[w:], rtol=1e-9, atol=1e-9)
    # the λ 0.03 scale's limit is the one-slow-scale detector's at half its share of the target
    half = LRGFGLR(**{**slow_det.get_params(), "slow_share": 0.25}).fit(train)
    assert det.stage_.h_dir_[2] == pytest.approx(half.stage_.h_dir_[1])
    assert det.stage_.h_dir_[0] == pytest.approx(
        slow_det.stage_.h_dir_[0]
    )  # the fast scale keeps its share
    det.save(tmp_path / "m")
    again = diagnosers.Diagnoser.load(tmp_path / "m")
    np.testing.assert_array_equal(again.detect(ep).signal, batch.signal)


def test_one_slow_scale_in_a_list_is_the_number(slow_det, train) -> None:
    det = LRGFGLR(**{**slow_det.get_params(), "slow_ewma_lambda": [0.03]}).fit(train)
    assert det.signal_names_ == slow_det.signal_names_
    np.testing.assert_array_equal(det.stage_.h_dir_, slow_det.stage_.h_dir_)


@pytest.mark.parametrize(
    "bad", [[0.03, 0.03], [0.0], [1.0], [], ["0.1"], "0.1", [0.1, float("nan")]]
)
def test_slow_scale_lists_are_refused_by_value(train, bad) -> None:
    with pytest.raises(ValueError, match=r"slow_ewma_lambda=.*a non-empty sequence of distinct"):
        LRGFGLR(**{**FAST, "slow_ewma_lambda": bad}).fit(train)


@pytest.mark.parametrize("bad", [0, -5, 2.5, "100", True])
def test_refit_epochs_outside_its_range_is_refused_by_name(train, bad) -> None:
    with pytest.raises(ValueError, match=r"refit_epochs=.* is outside the allowed range"):
        LRGFGLR(**{**FAST, "refit_epochs": bad}).fit(train)


# ---- the on-delay --------------------------------------------------------------------------------
@pytest.mark.parametrize("on_delay", [2, 5])
def test_on_delay_alarms_after_that_many_exceedances_in_a_row(
    slow_det, train, on_delay, tmp_path
) -> None:
    det = LRGFGLR(**{**slow_det.get_params(), "on_delay": on_delay}).fit(train)
    ep = inject_step_fault(make_episode(900, seed=9), onset=500, magnitude=1.5)
    batch = _stream_equals_batch(det, ep)
    # oracle: the run length of "some statistic over its limit", from the signal itself
    over = (batch.signal > batch.upper).any(axis=1)
    run = np.zeros(len(over), dtype=int)
    for k, o in enumerate(over):
        run[k] = run[k - 1] + 1 if o and k else int(o)
    np.testing.assert_array_equal(batch.alarm, run >= on_delay)
    assert over[det.steady_window :].any() and not over.all()  # the test has teeth
    assert batch.alarm.sum() < over.sum()
    # the limits stay per sample: without the on-delay the same fit alarms on every exceedance
    np.testing.assert_array_equal(det.stage_.upper_, slow_det.stage_.upper_)
    np.testing.assert_array_equal(slow_det.detect(ep).alarm, over)
    det.save(tmp_path / "m")
    again = diagnosers.Diagnoser.load(tmp_path / "m")
    assert again.on_delay == on_delay
    np.testing.assert_array_equal(again.detect(ep).alarm, batch.alarm)


@pytest.mark.parametrize("bad", [0, -1, 2.5, "3", 1001])
def test_on_delay_outside_its_range_is_refused_by_name(train, bad) -> None:
    with pytest.raises(ValueError, match=r"on_delay=.* is outside the allowed range"):
        LRGFGLR(**{**FAST, "on_delay": bad}).fit(train)


# ---- the regression baseline ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def regression_det(train) -> LRGFGLR:
    params = {**FAST, "n_folds": 2, "baseline_lambda": 1e-3, "baseline_settle": 300}
    params["baseline_hold"] = 1.0
    return LRGFGLR(**params, slow_ewma_lambda=0.0, baseline_filters=[1, 30]).fit(train)


def test_regression_baseline_stream_equals_batch_and_roundtrip(regression_det, tmp_path) -> None:
    det = regression_det
    ep = inject_step_fault(make_episode(900, seed=9), onset=500, magnitude=3.0)
    batch = _stream_equals_batch(det, ep)
    det.save(tmp_path / "m")
    again = diagnosers.Diagnoser.load(tmp_path / "m")
    assert again.baseline_filters == [1, 30] and again.baseline_ridge == 1.0
    np.testing.assert_array_equal(again.detect(ep).signal, batch.signal)


def _gain_mismatch(ep, gain: float):
    """Another plant: T_rg1 answers the air flow with ``gain`` °C per ton/h more than the
    training plants (and T_rg2 follows T_rg1 as before)."""
    y = ep.y.copy()
    i, o = ep.channels.index("R_ar"), ep.channels.index("T_rg1")
    y[:, o] += gain * (y[:, i] - y[:, i].mean())
    return diagnosers.Episode(y, ep.channels, ep.sample_time_s, fault_onset=ep.fault_onset)


def test_regression_baseline_learns_a_gain_the_running_mean_cannot(regression_det, train) -> None:
    # The mismatch moves with every air-flow step, so a constant cannot remove it; the
    # regression on the relation's filtered inputs learns it while settling.
    det = regression_det
    ep = _gain_mismatch(make_episode(2000, seed=21), 0.4)
    mean_only = LRGFGLR(**{**det.get_params(), "baseline_filters": None}).fit(train)
    w = det.steady_window + det.baseline_settle
    with_regression = det.detect(ep).alarm[w:].mean()
    with_mean = mean_only.detect(ep).alarm[w:].mean()
    assert with_mean > 0.3
    assert with_regression < 0.05
    # and a step fault that comes later is still found and kept in alarm
    faulty = _gain_mismatch(
        inject_step_fault(make_episode(2000, seed=22), onset=1200, magnitude=4.0), 0.05
    )
    alarm = det.detect(faulty).alarm
    assert alarm[1200:1230].any() and alarm[1250:].mean() > 0.9


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"baseline_filters": [0.5]}, r"baseline_filters=\[0.5\]"),
        ({"baseline_filters": []}, r"baseline_filters=\[\]"),
        ({"baseline_ridge": 0.0}, "baseline_ridge=0.0"),
        ({"baseline_filters": [1, 30], "baseline_lambda": 0.0}, "needs a baseline"),
    ],
)
def test_regression_baseline_parameters_are_checked(train, changes, match) -> None:
    params = {**FAST, "baseline_lambda": 1e-3, **changes}
    with pytest.raises(ValueError, match=match):
        LRGFGLR(**params).fit(train)
