"""Tests of the NNARX model error model and the bands (diagnosers.networks.mem_net, mem_stepper, band; diagnosers.networks.training.fit_mem)."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
import torch
from scipy import signal as sps

from diagnosers.networks.mem_net import NNARXErrorModel
from diagnosers.networks.mem_stepper import MEMBankStepper, MEMStepper
from diagnosers.networks.modules import build_module, export_module, paper_mem
from diagnosers.networks.training import fit_mem
from diagnosers.stages.alarm import two_sided_normal_quantile
from diagnosers.stages.band import band, band_scale


def _steps(rng: np.random.Generator, t_len: int, n: int, hold: int = 40) -> np.ndarray:
    k = -(-t_len // hold)
    return np.repeat(rng.uniform(-1.0, 1.0, size=(k, n)), hold, axis=0)[:t_len]


def _plant(rng: np.random.Generator, t_len: int) -> dict[str, np.ndarray]:
    """Synthetic plant: the nominal model gets the static part, it misses a slow linear dynamic.

    ``y = 300 + 5 u_1 - 2 u_2 + slow(u) + noise``, ``y_m = 300 + 5 u_1 - 2 u_2``; so the residual is
    ``slow(u) + noise``, with ``slow`` a first-order lag (pole 0.95) of a mix of the inputs, and
    white Gaussian noise (std 0.05). The plant starts at rest at ``u(0)``.
    """
    u = 50.0 + 10.0 * _steps(rng, t_len, 2)
    un = (u - 50.0) / 10.0
    x = un[:, 0] - 0.5 * un[:, 1]
    # the plant starts at rest at u(0), as FCC episodes do (and as the MEM assumes)
    slow, _ = sps.lfilter([0, 0.05], [1, -0.95], x, zi=sps.lfilter_zi([0, 0.05], [1, -0.95]) * x[0])
    y_m = 300.0 + 5.0 * un[:, 0] - 2.0 * un[:, 1]
    y = y_m + slow + 0.05 * rng.standard_normal(t_len)
    return {"u": u, "y": y[:, None], "y_m": y_m[:, None], "r": (y - y_m)[:, None]}


# ---- simulation ----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("n", "m", "nb", "na", "act"),
    [(2, 1, 15, 15, "linear"), (1, 1, 3, 0, "linear"), (3, 2, 2, 4, "tanh"), (2, 1, 1, 1, "tanh")],
)
def test_streaming_equals_batch_simulation(n: int, m: int, nb: int, na: int, act: str) -> None:
    mem = NNARXErrorModel(
        n, m, n_hidden=4, input_delays=nb, output_delays=na, output_activation=act, seed=3
    ).double()
    with torch.no_grad():
        mem.hidden.weight.mul_(3.0)  # strong feedback, so the recursion matters
        mem.out.bias.fill_(0.1)
    mem.set_scaler(np.arange(n) + 1.0, np.full(n, 2.0), np.full(m, -4.0), np.full(m, 0.5))
    u = 1.0 + 2.0 * np.random.default_rng(0).normal(size=(400, n))
    ye = mem.predict(u)
    st = MEMStepper(mem)
    ye_stream = np.stack([st.step(row) for row in u])
    np.testing.assert_allclose(ye_stream, ye, rtol=0, atol=1e-9)
    st.reset()  # a new episode starts from the same state
    np.testing.assert_allclose(
        np.stack([st.step(row) for row in u[:10]]), ye[:10], rtol=0, atol=1e-9
    )


def test_regressors_by_their_definition() -> None:
    """``lagged_inputs``/``lagged_outputs`` against an index-by-index build, and the cached
    regressors give the drive and the one-step prediction to the bit."""
    n, m, nb, na, t_len = 2, 1, 4, 3, 30
    mem = NNARXErrorModel(n, m, n_hidden=3, input_delays=nb, output_delays=na, seed=1).double()
    rng = np.random.default_rng(2)
    u = torch.as_tensor(rng.normal(size=(2, t_len, n)))
    y = torch.as_tensor(rng.normal(size=(2, t_len, m)))
    lu, ly = mem.lagged_inputs(u).numpy(), mem.lagged_outputs(y).numpy()
    assert lu.shape == (2, t_len, nb * n) and ly.shape == (2, t_len, na * m)
    for k in range(t_len):
        for d in range(1, nb + 1):  # u(k - d), held at u(0) before the start
            np.testing.assert_array_equal(lu[:, k, (d - 1) * n : d * n], u[:, max(k - d, 0)])
        for d in range(1, na + 1):  # y(k - d), zero before the start
            want = y[:, k - d] if k - d >= 0 else np.zeros((2, m))
            np.testing.assert_array_equal(ly[:, k, (d - 1) * m : d * m], want)
    with torch.no_grad():
        drive = mem.input_drive(u)
        assert torch.equal(mem.input_drive(u, mem.lagged_inputs(u)), drive)
        assert torch.equal(
            mem.one_step_normalized(drive, y, mem.lagged_outputs(y)),
            mem.one_step_normalized(drive, y),
        )


def test_bank_stepper_equals_each_models_stepper() -> None:
    """Models of different sizes, delays and output activations, stacked with zero padding."""
    shapes = [(2, 4, 15, 15, "linear"), (1, 3, 3, 0, "tanh"), (3, 6, 2, 4, "linear")]
    mems, idx = [], [np.array([3, 0]), np.array([2]), np.array([1, 4, 0])]
    for j, (n, h, nb, na, act) in enumerate(shapes):
        mem = NNARXErrorModel(
            n, n_hidden=h, input_delays=nb, output_delays=na, output_activation=act, seed=j
        ).double()
        with torch.no_grad():
            mem.hidden.weight.mul_(3.0)  # strong feedback, so the recursion matters
        mem.set_scaler(np.arange(n) + 1.0, np.full(n, 2.0), np.full(1, -4.0), np.full(1, 0.5))
        mems.append(mem)
    y = 1.0 + 2.0 * np.random.default_rng(0).normal(size=(300, 5))
    bank = MEMBankStepper(mems, idx)
    stepped = np.stack([bank.step(row) for row in y])
    for j, (mem, i) in enumerate(zip(mems, idx, strict=True)):
        st = MEMStepper(mem)
        one = np.stack([st.step(row) for row in y[:, i]])[:, 0]
        np.testing.assert_allclose(stepped[:, j], one, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(stepped[:, j], mem.predict(y[:, i])[:, 0], rtol=0, atol=1e-9)
    bank.reset()
    np.testing.assert_array_equal(np.stack([bank.step(row) for row in y[:20]]), stepped[:20])


def test_start_convention_and_causality() -> None:
    mem = NNARXErrorModel(2, input_delays=3, output_delays=2, seed=1).double()
    u = np.random.default_rng(1).normal(size=(60, 2))
    ye = mem.predict(u)
    # before k = 0 the inputs sat at u(0) and the past outputs are 0 (standardised units)
    w = mem.hidden.weight.detach().numpy()
    pre0 = w[:, :6] @ np.tile(u[0], 3) + mem.hidden.bias.detach().numpy()
    ref0 = mem.out.weight.detach().numpy() @ np.tanh(pre0) + mem.out.bias.detach().numpy()
    np.testing.assert_allclose(ye[0], ref0, atol=1e-12)
    # y_e(k) uses u up to k-1 only: changing u(30) leaves y_e(0..30) unchanged, moves y_e(31)
    u2 = u.copy()
    u2[30] += 5.0
    ye2 = mem.predict(u2)
    np.testing.assert_array_equal(ye2[:31], ye[:31])
    assert abs(ye2[31, 0] - ye[31, 0]) > 1e-6


def test_streaming_is_fast() -> None:
    mem = paper_mem(seed=0).double()
    st = MEMStepper(mem)
    u = np.random.default_rng(0).normal(size=(20000, 2))
    best = 0.0
    for _ in range(3):
        st.reset()
        t0 = time.perf_counter()
        for row in u:
            st.step(row)
        best = max(best, len(u) / (time.perf_counter() - t0))
    assert best >= 10_000, f"MEM streaming runs at {best:.0f} samples/s"


# ---- bands ---------------------------------------------------------------------------------------
def test_two_sided_quantile_and_band_formula() -> None:
    assert two_sided_normal_quantile(0.01) == pytest.approx(2.5758, abs=1e-4)
    assert two_sided_normal_quantile(0.05) == pytest.approx(1.9600, abs=1e-4)
    y_m = np.array([[1.0], [2.0], [3.0]])
    y_e = np.array([[0.5], [-0.5], [0.0]])
    lo, hi = band(y_m, y_e, np.array([2.0]), alpha=0.01)
    np.testing.assert_allclose(lo, y_m + y_e - 2.0 * 2.5758293035489, rtol=1e-12)
    np.testing.assert_allclose(hi, y_m + y_e + 2.0 * 2.5758293035489, rtol=1e-12)
    with pytest.raises(ValueError, match="alpha"):
        two_sided_normal_quantile(1.5)


def test_band_scale_definitions() -> None:
    rng = np.random.default_rng(0)
    y_e = rng.normal(size=(500, 2))
    y_m = rng.normal(size=(500, 2))
    y = y_m + y_e + 0.1 * rng.normal(size=(500, 2))
    np.testing.assert_allclose(band_scale(y_e, definition="paper"), y_e.std(axis=0, ddof=1))
    np.testing.assert_allclose(
        band_scale(y_e, definition="residual", y=y, y_m=y_m), (y - y_m - y_e).std(axis=0, ddof=1)
    )
    with pytest.raises(ValueError, match="needs the measured y"):
        band_scale(y_e, definition="residual")
    with pytest.raises(ValueError, match="definition"):
        band_scale(y_e, definition="bootstrap")


# ---- training --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def trained() -> dict:
    rng = np.random.default_rng(7)
    train, calib, test = _plant(rng, 2500), _plant(rng, 2000), _plant(rng, 3000)
    mem = NNARXErrorModel(2, n_hidden=5, input_delays=4, output_delays=4, seed=0)
    res = fit_mem(mem, train["u"], train["r"], max_epochs=150, lr=0.02, seed=0)
    return {"mem": mem, "res": res, "train": train, "calib": calib, "test": test}


def test_mem_reduces_residual(trained: dict) -> None:
    test, mem = trained["test"], trained["mem"]
    r = test["r"]
    ye = mem.predict(test["u"])
    rms_before = np.sqrt(np.mean((r - r.mean()) ** 2))
    rms_after = np.sqrt(np.mean((r - ye) ** 2))
    assert rms_after < 0.4 * rms_before, (rms_before, rms_after)
    assert trained["res"].best_val_loss == pytest.approx(min(trained["res"].val_loss))


def test_residual_band_coverage(trained: dict) -> None:
    """Band (10)-(11) with v from held-out healthy data covers ~1-α of new healthy data."""
    mem, calib, test = trained["mem"], trained["calib"], trained["test"]
    v = band_scale(mem.predict(calib["u"]), definition="residual", y=calib["y"], y_m=calib["y_m"])
    lo, hi = band(test["y_m"], mem.predict(test["u"]), v, alpha=0.01)
    coverage = np.mean((test["y"] >= lo) & (test["y"] <= hi))
    # Nominal is 0.99. The MEM misses part of the lag (simulation RMS ~0.09 against a 0.05 noise
    # floor) and that misfit differs between episodes, so calibration under-estimates it a little;
    # measured 0.967 here. 0.95 still fails a band built with the wrong scale or quantile.
    assert coverage >= 0.95, coverage
    # and the band is much narrower than one built on the raw residual spread
    assert v[0] < 0.5 * calib["r"].std()


def test_fit_mem_deterministic_and_global_rng_untouched(trained: dict) -> None:
    u, r = trained["train"]["u"][:800], trained["train"]["r"][:800]
    torch_state, np_state = torch.get_rng_state(), np.random.get_state()
    mems = []
    for seed in (3, 3, 4):
        mem = NNARXErrorModel(2, input_delays=3, output_delays=3, seed=0)
        # no warm start, so the seeded window offsets decide the result
        fit_mem(mem, u, r, max_epochs=15, window=64, seed=seed, pretrain_epochs=0, patience=100)
        mems.append(mem)
    for (k, a), b in zip(mems[0].state_dict().items(), mems[1].state_dict().values(), strict=True):
        assert torch.equal(a, b), k
    assert not torch.equal(mems[0].hidden.weight, mems[2].hidden.weight)  # window offsets differ
    assert torch.equal(torch.get_rng_state(), torch_state)
    new_np = np.random.get_state()
    assert np.array_equal(new_np[1], np_state[1])


def test_fit_mem_validation_episodes_and_errors(trained: dict) -> None:
    tr = trained["train"]
    mem = NNARXErrorModel(2, input_delays=2, output_delays=2)
    res = fit_mem(
        mem,
        [tr["u"][:900], tr["u"][900:1500]],
        [tr["r"][:900], tr["r"][900:1500]],
        u_val=tr["u"][1500:],
        r_val=tr["r"][1500:],
        max_epochs=10,
        val_every=2,
    )
    assert len(res.val_loss) == 6 and np.isfinite(res.val_loss).all()
    with pytest.raises(ValueError, match="shape"):
        fit_mem(mem, tr["u"][:, :1], tr["r"])
    with pytest.raises(ValueError, match="window"):
        fit_mem(mem, tr["u"], tr["r"], window=1)


# ---- persistence -------------------------------------------------------------------------------------
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_persistence_round_trip(tmp_path, trained: dict, dtype: torch.dtype) -> None:
    mem = trained["mem"]
    src = NNARXErrorModel.from_config(mem.get_config()).to(dtype)
    src.load_state_dict(mem.state_dict())
    config, state = export_module(src)
    torch.save(state, tmp_path / "mem.pt")
    (tmp_path / "mem.json").write_text(json.dumps(config))
    mem2 = build_module(
        json.loads((tmp_path / "mem.json").read_text()),
        torch.load(tmp_path / "mem.pt", weights_only=True),
    )
    assert isinstance(mem2, NNARXErrorModel) and mem2.hidden.weight.dtype == dtype
    u = trained["test"]["u"][:300]
    np.testing.assert_array_equal(mem2.predict(u), src.predict(u))
    np.testing.assert_array_equal(mem2.output_mean.numpy(), src.output_mean.numpy())
