"""Tests of the LRGF network (diagnosers.networks.lrgf_net) and its trainer (diagnosers.networks.training.fit_lrgf)."""

from __future__ import annotations

import mpmath
import numpy as np
import pytest
import torch
from scipy import signal as sps
from torch.func import functional_call

from diagnosers.networks.iir import (
    denominator_from_reflection,
    iir_filter,
    reflection_from_denominator,
)
from diagnosers.networks.lrgf_fused import lrgf_free_run
from diagnosers.networks.lrgf_net import LRGF, lrgf_activation
from diagnosers.networks.lrgf_stepper import LRGFStepper
from diagnosers.networks.modules import build_module, export_module
from diagnosers.networks.optimisers import SPSAOptions
from diagnosers.networks.training import fit_lrgf


def _steps(rng: np.random.Generator, t_len: int, n: int, hold: int = 50) -> np.ndarray:
    """Random-step excitation, levels uniform in [-1, 1], held ``hold`` samples."""
    k = -(-t_len // hold)
    return np.repeat(rng.uniform(-1.0, 1.0, size=(k, n)), hold, axis=0)[:t_len]


def _fit_percent(y: np.ndarray, y_hat: np.ndarray) -> float:
    return float(100.0 * (1.0 - np.linalg.norm(y - y_hat) / np.linalg.norm(y - y.mean())))


def _state_space_oracle(net: LRGF, u_n: np.ndarray) -> np.ndarray:
    """Per-sample simulation of eqs. (1)-(3): x(k+1) = A_i x(k) + 1 w_i u(k), z = b_i x + b0_i w_i u."""
    w = net.weight_in.detach().double().numpy()
    b = net.b.detach().double().numpy()
    b0 = net.b0.detach().double().numpy()
    _, den = net.filter_coefficients()
    a = den.detach().numpy()
    v, r = a.shape
    bsz, t_len, _ = u_n.shape
    z = np.zeros((bsz, t_len, v))
    for i in range(v):
        a_mat = np.zeros((r, r))
        a_mat[0] = -a[i]
        a_mat[1:, :-1] = np.eye(r - 1)
        ones = np.ones(r)  # the paper's input vector of ones, not e_1
        for bb in range(bsz):
            x = np.zeros(r)
            for k in range(t_len):
                s = w[i] @ u_n[bb, k]
                z[bb, k, i] = b[i] @ x + b0[i] * s
                x = a_mat @ x + ones * s
    return z


# ---- linear part -------------------------------------------------------------------------------
@pytest.mark.parametrize("order", [1, 2, 3, 4])
def test_linear_part_equals_state_space_oracle_and_lfilter(order: int) -> None:
    net = LRGF(2, 3, order, 1, seed=order).double()
    u_n = np.random.default_rng(order).normal(size=(2, 60, 2))
    z = net.linear_part(torch.from_numpy(u_n)).detach().numpy()
    np.testing.assert_allclose(z, _state_space_oracle(net, u_n), rtol=0, atol=1e-11)
    num, den = (t.detach().numpy() for t in net.filter_coefficients())
    s = u_n @ net.weight_in.detach().numpy().T
    for i in range(3):
        ref = sps.lfilter(num[i], np.r_[1.0, den[i]], s[:, :, i], axis=1)
        np.testing.assert_allclose(z[:, :, i], ref, rtol=0, atol=1e-12)


def test_iir_filter_equals_lfilter_float32() -> None:
    rng = np.random.default_rng(0)
    x = rng.normal(size=(3, 200, 2)).astype(np.float32)
    num = np.array([[0.5, -0.2, 0.1], [1.0, 0.3, 0.0]])
    den = np.array([[-1.5, 0.7], [-0.2, 0.05]])
    y = iir_filter(torch.from_numpy(x), torch.from_numpy(num), torch.from_numpy(den))
    assert y.dtype == torch.float32
    for c in range(2):
        ref = sps.lfilter(num[c], np.r_[1.0, den[c]], x[:, :, c].astype(np.float64), axis=1)
        np.testing.assert_allclose(y[:, :, c].numpy(), ref, rtol=1e-5, atol=1e-5)


def test_known_second_order_step_response() -> None:
    """Golden case worked by hand: poles 0.9 and 0.5, ``b = [1, 0]``, ``b0 = 0``, ``w = 1``."""
    net = LRGF(1, 1, 2, 1, seed=0).double()
    k = reflection_from_denominator(np.poly(np.array([0.9, 0.5]) / net.max_pole_radius)[1:])
    with torch.no_grad():
        net.reflection_raw.copy_(torch.from_numpy(np.arctanh(k / 0.999))[None])
        net.b.copy_(torch.tensor([[1.0, 0.0]]))
        net.b0.zero_()
        net.weight_in.fill_(1.0)
    num, den = (t.detach() for t in net.filter_coefficients())
    np.testing.assert_allclose(den.numpy()[0], [-1.4, 0.45], atol=1e-12)
    # x1(k+1) = 1.4 x1 - 0.45 x2 + s, x2(k+1) = x1 + s: b (qI-A)^-1 1 = (q - 0.45)/(q^2 - 1.4q + 0.45)
    np.testing.assert_allclose(num.numpy()[0], [0.0, 1.0, -0.45], atol=1e-12)
    z = net.linear_part(torch.ones(1, 400, 1, dtype=torch.float64)).detach().numpy()[0, :, 0]
    assert z[0] == 0.0 and z[1] == pytest.approx(1.0)
    assert z[-1] == pytest.approx(0.55 / 0.05, rel=1e-9)  # static gain H(1)


# ---- gradients ---------------------------------------------------------------------------------
@pytest.mark.parametrize(("nb", "na"), [(3, 2), (1, 1), (4, 1), (2, 3)])
def test_gradcheck_iir_filter(nb: int, na: int) -> None:
    gen = torch.Generator().manual_seed(nb * 10 + na)
    x = torch.randn(2, 15, 3, dtype=torch.float64, generator=gen, requires_grad=True)
    num = torch.randn(3, nb, dtype=torch.float64, generator=gen, requires_grad=True)
    k = 0.8 * torch.tanh(torch.randn(3, na, dtype=torch.float64, generator=gen))
    den = denominator_from_reflection(k).detach().requires_grad_(True)
    assert torch.autograd.gradcheck(iir_filter, (x, num, den))


@pytest.mark.parametrize("initial_state", ["zero", "steady"])
@pytest.mark.parametrize("output_bias", [False, True])
def test_gradcheck_whole_network(initial_state: str, output_bias: bool) -> None:
    net = LRGF(2, 2, 2, 2, initial_state=initial_state, output_bias=output_bias, seed=3).double()
    with torch.no_grad():
        net.set_scaler([0.5, -1.0], [2.0, 0.5], [1.0, 3.0], [0.7, 1.5])
    names = [n for n, _ in net.named_parameters()]
    params = tuple(p.detach().clone().requires_grad_(True) for _, p in net.named_parameters())
    u = torch.randn(2, 12, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    u.requires_grad_(True)

    def f(u_in: torch.Tensor, *ps: torch.Tensor) -> torch.Tensor:
        return functional_call(net, dict(zip(names, ps, strict=True)), (u_in,))

    assert torch.autograd.gradcheck(f, (u, *params))


# ---- stability ---------------------------------------------------------------------------------
def _exact_max_pole_modulus(den: np.ndarray) -> float:
    """Largest pole modulus of ``1 + den(q^-1)`` in 60-digit arithmetic.

    float64 ``np.roots`` finds an r-fold root only to about ``eps**(1/r)`` (1e-3 for r = 5), which
    is larger than the stability margin for saturated high-order filters; the coefficients are
    exact binary fractions, so multiprecision roots are the true poles of the filter in use.
    """
    with mpmath.workdps(60):
        roots = mpmath.polyroots([1.0, *den.tolist()], maxsteps=500, extraprec=300)
        return float(max(abs(z) for z in roots))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("order", [1, 2, 3, 4, 6, 8])
def test_poles_inside_unit_circle_for_any_parameters(dtype: torch.dtype, order: int) -> None:
    net = LRGF(1, 4, order, 1, seed=0).to(dtype)
    rho = net.max_pole_radius
    gen = torch.Generator().manual_seed(order)
    draws = [
        s * torch.randn(4, order, generator=gen, dtype=dtype) for s in (0.1, 1.0, 10.0, 1e3, 1e6)
    ]
    draws += [torch.full((4, order), 1e30, dtype=dtype), torch.full((4, order), -1e30, dtype=dtype)]
    draws += [1e4 * torch.sign(torch.randn(4, order, generator=gen, dtype=dtype)) for _ in range(3)]
    for theta in draws:
        with torch.no_grad():
            net.reflection_raw.copy_(theta)
        if order <= 4 or theta.abs().max() <= 1.0:  # where float64 np.roots is accurate enough
            assert np.abs(net.poles()).max() < 1.0
        _, den = net.filter_coefficients()
        for row in den.detach().numpy():
            assert _exact_max_pole_modulus(row) <= rho + 1e-8  # float64 rounding


def test_step_down_inverts_step_up() -> None:
    rng = np.random.default_rng(0)
    for r in range(1, 7):
        k = rng.uniform(-0.99, 0.99, size=r)
        a = denominator_from_reflection(torch.from_numpy(k)).numpy()
        np.testing.assert_allclose(reflection_from_denominator(a), k, atol=1e-9)
        assert np.abs(np.roots(np.r_[1.0, a])).max() < 1.0
    with pytest.raises(ValueError, match="not stable"):
        reflection_from_denominator(np.poly([1.2, 0.3])[1:])


# ---- structure ---------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("n", "v", "r", "m"), [(1, 1, 1, 1), (2, 3, 2, 1), (4, 5, 3, 2), (3, 2, 8, 4)]
)
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_shapes_and_dtypes(n: int, v: int, r: int, m: int, dtype: torch.dtype) -> None:
    net = LRGF(n, v, r, m, seed=1).to(dtype)
    y = net(torch.randn(3, 17, n, dtype=dtype))
    assert y.shape == (3, 17, m) and y.dtype == dtype
    assert np.isfinite(y.detach().numpy()).all()
    assert all(torch.isfinite(p).all() for p in net.parameters())
    num, den = net.filter_coefficients()
    assert num.shape == (v, r + 1) and den.shape == (v, r)
    assert net.predict(np.zeros((9, n))).shape == (9, m)


def test_activation_is_eq5() -> None:
    z = torch.linspace(-5, 5, 101, dtype=torch.float64)
    g1, g2 = torch.tensor(0.3, dtype=torch.float64), torch.tensor(1.7, dtype=torch.float64)
    e = torch.exp(-g2 * (z - g1))
    torch.testing.assert_close(lrgf_activation(z, g1, g2), (1 - e) / (1 + e))


def test_bad_arguments_raise() -> None:
    with pytest.raises(ValueError, match="order"):
        LRGF(2, 3, 0)
    with pytest.raises(ValueError, match="initial_state"):
        LRGF(2, 3, 2, initial_state="warm")
    with pytest.raises(ValueError, match=r"\(batch, time, 2\)"):
        LRGF(2, 3, 2)(torch.zeros(10, 2))
    with pytest.raises(ValueError, match="method"):
        fit_lrgf(LRGF(1, 1, 1), np.zeros((50, 1)), np.zeros((50, 1)), method="lbfgs")


@pytest.mark.parametrize(
    ("initial_state", "steady_window"),
    [("zero", 1), ("steady", 1), ("steady", 7), ("steady", 300), ("steady", 1000)],
)
def test_stepper_equals_batch(initial_state: str, steady_window: int) -> None:
    net = LRGF(
        2,
        3,
        3,
        2,
        initial_state=initial_state,
        steady_window=steady_window,
        output_bias=True,
        seed=5,
    ).double()
    with torch.no_grad():
        net.set_scaler([1.0, 2.0], [0.5, 3.0], [10.0, -1.0], [2.0, 0.1])
        net.bias_out.fill_(0.2)
    u = 1.0 + np.random.default_rng(0).normal(size=(300, 2))
    st = LRGFStepper(net)
    y_stream = np.stack([st.step(row) for row in u])
    np.testing.assert_allclose(y_stream, net.predict(u), rtol=0, atol=1e-10)
    st.reset()
    np.testing.assert_allclose(st.step(u[0]), y_stream[0], rtol=0, atol=1e-12)


def test_steady_initial_state_has_no_transient() -> None:
    net = LRGF(2, 3, 2, 1, initial_state="steady", seed=2).double()
    y = net.predict(np.tile([0.7, -1.3], (200, 1)))
    np.testing.assert_allclose(y, np.full_like(y, y[0, 0]), rtol=0, atol=1e-12)
    y_zero = LRGF(2, 3, 2, 1, seed=2).double().predict(np.tile([0.7, -1.3], (200, 1)))
    assert np.ptp(y_zero) > 1e-3  # the zero state does show a start-up transient
    np.testing.assert_allclose(y_zero[-1], y[-1], atol=1e-6)


def test_steady_window_starts_from_the_running_mean() -> None:
    rng = np.random.default_rng(7)
    u = np.tile([0.7, -1.3], (300, 1)) + rng.normal(scale=0.2, size=(300, 2))
    net = LRGF(2, 3, 2, 1, initial_state="steady", steady_window=40, seed=2).double()
    y = net.predict(u)
    # during the window: the steady response to the mean of the inputs so far
    for k in (0, 9, 39):
        level = np.tile(u[: k + 1].mean(0), (5, 1))
        np.testing.assert_allclose(y[k], net.predict(level)[0], rtol=0, atol=1e-12)
    # after it: the ordinary filter started at steady state for the window mean
    head = np.tile(u[:40].mean(0), (40, 1))
    ref = (
        LRGF(2, 3, 2, 1, initial_state="steady", seed=2).double().predict(np.vstack([head, u[40:]]))
    )
    np.testing.assert_allclose(y[40:], ref[40:], rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="steady_window=0 must be a positive integer"):
        LRGF(2, 3, 2, 1, steady_window=0)


def test_steady_window_survives_export() -> None:
    net = LRGF(2, 3, 2, 1, initial_state="steady", steady_window=25, seed=2).double()
    config, state = export_module(net)
    assert config["steady_window"] == 25
    assert build_module(config, state).steady_window == 25
    del config["steady_window"]  # files written before the option start from the first sample
    assert build_module(config, state).steady_window == 1


# ---- training ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def teacher_data() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(2024)
    teacher = LRGF(2, 3, 2, 1, seed=123).double()
    # physical units far from 0/1 (temperatures), so the scaler matters
    teacher.set_scaler([400.0, 400.0], [30.0, 30.0], [500.0], [20.0])
    u, u_test = 400.0 + 30.0 * _steps(rng, 2500, 2), 400.0 + 30.0 * _steps(rng, 1500, 2)
    return {"u": u, "y": teacher.predict(u), "u_test": u_test, "y_test": teacher.predict(u_test)}


def test_teacher_student_recovery(teacher_data: dict[str, np.ndarray]) -> None:
    student = LRGF(2, 3, 2, 1, seed=7)
    res = fit_lrgf(student, teacher_data["u"], teacher_data["y"], max_epochs=1200, lr=0.02)
    assert res.best_val_loss < res.val_loss[0] / 20
    fit = _fit_percent(teacher_data["y_test"], student.predict(teacher_data["u_test"]))
    assert fit >= 95.0, f"student fit {fit:.1f}% on held-out data"
    # the scaler maps back to physical units
    assert student.output_mean.item() == pytest.approx(teacher_data["y"][:1875].mean(), rel=1e-5)


def test_training_is_deterministic_and_leaves_global_rng_alone(
    teacher_data: dict[str, np.ndarray],
) -> None:
    u, y = teacher_data["u"][:800], teacher_data["y"][:800]
    torch_state, np_state = torch.get_rng_state(), np.random.get_state()
    threads = torch.get_num_threads()
    nets = []
    for method in ("adam", "adam", "spsa", "spsa"):
        net = LRGF(2, 3, 2, 1, seed=11)
        fit_lrgf(net, u, y, method=method, max_epochs=60, seed=5)
        nets.append(net)
    for a, b in ((nets[0], nets[1]), (nets[2], nets[3])):
        for (k, p), q in zip(a.state_dict().items(), b.state_dict().values(), strict=True):
            assert torch.equal(p, q), k
    assert not torch.equal(nets[0].weight_in, nets[2].weight_in)
    assert torch.equal(torch.get_rng_state(), torch_state)
    new_np = np.random.get_state()
    assert new_np[0] == np_state[0] and np.array_equal(new_np[1], np_state[1])
    assert torch.get_num_threads() == threads


def test_spsa_reduces_the_loss(teacher_data: dict[str, np.ndarray]) -> None:
    net = LRGF(2, 3, 2, 1, seed=7)
    res = fit_lrgf(
        net,
        teacher_data["u"],
        teacher_data["y"],
        method="spsa",
        max_epochs=800,
        spsa=SPSAOptions(initial_step=0.05),
        seed=1,
    )
    assert res.method == "spsa" and res.n_epochs == 800
    assert res.best_val_loss < 0.3 * res.val_loss[0]
    # blocking makes the training loss monotone
    assert all(b <= a for a, b in zip(res.train_loss, res.train_loss[1:], strict=False))


def test_early_stopping_restores_best(teacher_data: dict[str, np.ndarray]) -> None:
    net = LRGF(2, 3, 2, 1, seed=7)
    u, y = teacher_data["u"][:600], teacher_data["y"][:600]
    res = fit_lrgf(net, u, y, max_epochs=400, lr=0.5, patience=20)  # a wild lr to provoke it
    assert res.stopped_early and res.n_epochs < 400
    assert res.best_val_loss == pytest.approx(min(res.val_loss))
    # the restored weights reproduce the best validation loss
    res2 = fit_lrgf(net, u, y, max_epochs=1, standardize=False)
    assert res2.val_loss[0] == pytest.approx(res.best_val_loss, rel=1e-5)


def test_explicit_validation_episodes_and_lists(teacher_data: dict[str, np.ndarray]) -> None:
    u, y = teacher_data["u"], teacher_data["y"]
    net = LRGF(2, 3, 2, 1, seed=7)
    res = fit_lrgf(
        net,
        [u[:1000], u[1000:1700]],
        [y[:1000], y[1000:1700]],
        u_val=u[1700:],
        y_val=y[1700:],
        max_epochs=30,
        washout=10,
    )
    assert len(res.val_loss) == 30 and np.isfinite(res.val_loss).all()


# ---- persistence -------------------------------------------------------------------------------
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_persistence_round_trip(tmp_path, dtype: torch.dtype) -> None:
    import json

    net = LRGF(2, 3, 2, 1, output_bias=True, initial_state="steady", seed=4).to(dtype)
    net.set_scaler([1.0, 2.0], [3.0, 4.0], [5.0], [6.0])
    config, state = export_module(net)
    torch.save(state, tmp_path / "w.pt")
    (tmp_path / "c.json").write_text(json.dumps(config))
    loaded = torch.load(tmp_path / "w.pt", weights_only=True)
    net2 = build_module(json.loads((tmp_path / "c.json").read_text()), loaded)
    assert isinstance(net2, LRGF) and net2.weight_in.dtype == dtype
    u = np.random.default_rng(0).normal(size=(100, 2))
    np.testing.assert_array_equal(net2.predict(u), net.predict(u))
    with pytest.raises(ValueError, match="unknown module kind"):
        build_module({"kind": "gru"}, loaded)


# ---- fused free run (diagnosers.networks.lrgf_fused) against the torch-autograd reference ---------------
@pytest.mark.parametrize(
    ("initial_state", "steady_window", "t_len"),
    [("zero", 1, 300), ("steady", 1, 300), ("steady", 50, 300), ("steady", 300, 300),
     ("steady", 400, 300), ("steady", 7, 8)],
)  # fmt: skip
@pytest.mark.parametrize("output_bias", [False, True])
@pytest.mark.parametrize(("order", "n_linear"), [(1, 0), (2, 0), (3, 0), (2, 1), (1, 4)])
def test_fused_free_run_equals_reference_values_and_gradients(
    initial_state: str, steady_window: int, t_len: int, output_bias: bool, order: int,
    n_linear: int,
) -> None:  # fmt: skip
    net = LRGF(
        3, 4, order, 2, output_bias=output_bias, initial_state=initial_state,
        steady_window=steady_window, seed=order, n_linear=n_linear,
    ).double()  # fmt: skip
    rng = np.random.default_rng(order)
    u = torch.from_numpy(np.cumsum(rng.normal(size=(2, t_len, 3)), axis=1) * 0.1)
    u.requires_grad_(True)
    weights = torch.from_numpy(rng.normal(size=(2, t_len, 2)))
    leaves = [u, *net.parameters()]
    ref = net.forward_reference(u)
    new = net.forward_normalized(u)
    np.testing.assert_allclose(new.detach().numpy(), ref.detach().numpy(), rtol=0, atol=1e-13)
    g_ref = torch.autograd.grad((ref * weights).sum(), leaves)
    g_new = torch.autograd.grad((new * weights).sum(), leaves)
    for a, b in zip(g_ref, g_new, strict=True):
        np.testing.assert_allclose(b.numpy(), a.numpy(), rtol=1e-10, atol=1e-12)


def test_fused_free_run_float32_matches_reference() -> None:
    net = LRGF(2, 3, 2, 1, output_bias=True, initial_state="steady", steady_window=20, seed=5)
    u = torch.randn(3, 200, 2, generator=torch.Generator().manual_seed(1))
    new, ref = net.forward_normalized(u), net.forward_reference(u)
    assert new.dtype == torch.float32
    np.testing.assert_allclose(new.detach().numpy(), ref.detach().numpy(), atol=1e-5)
    (new.sum()).backward()
    assert all(p.grad is not None and p.grad.dtype == torch.float32 for p in net.parameters())


@pytest.mark.parametrize(("steady_window", "n_linear"), [(0, 0), (1, 0), (5, 0), (5, 1), (0, 3)])
def test_gradcheck_fused_free_run(steady_window: int, n_linear: int) -> None:
    gen = torch.Generator().manual_seed(steady_window)

    def rand(*shape: int) -> torch.Tensor:
        return torch.randn(*shape, dtype=torch.float64, generator=gen).requires_grad_(True)

    k = 0.8 * torch.tanh(torch.randn(3, 2, dtype=torch.float64, generator=gen))
    den = denominator_from_reflection(k).detach().requires_grad_(True)
    args = (
        rand(2, 11, 2),
        rand(3, 2),
        rand(3, 3),
        den,
        rand(3),
        0.5 + torch.rand(3, dtype=torch.float64, generator=gen).requires_grad_(True),
        rand(2, 3),
        rand(2),
    )
    assert torch.autograd.gradcheck(
        lambda *a: lrgf_free_run(*a, steady_window=steady_window, n_linear=n_linear), args
    )


def test_fused_free_run_refuses_bad_input() -> None:
    w = torch.zeros(3, 2, dtype=torch.float64)
    args = (
        w,
        torch.zeros(3, 3),
        torch.zeros(3, 2),
        torch.zeros(3),
        torch.ones(3),
        torch.zeros(1, 3),
    )
    with pytest.raises(ValueError, match=r"u_n must have shape \(batch, time, 2\)"):
        lrgf_free_run(torch.zeros(4, 2), *args)
    with pytest.raises(ValueError, match="steady_window=-1"):
        lrgf_free_run(torch.zeros(1, 4, 2), *args, steady_window=-1)
    with pytest.raises(ValueError, match=r"g1 has shape \(2,\); allowed: \(3,\) for 3 neurons"):
        lrgf_free_run(torch.zeros(1, 4, 2), *args[:3], torch.zeros(2), *args[4:])
    with pytest.raises(ValueError, match=r"den has shape \(3, 1\); allowed: \(3, 2\)"):
        lrgf_free_run(torch.zeros(1, 4, 2), args[0], args[1], torch.zeros(3, 1), *args[3:])
    with pytest.raises(ValueError, match=r"weight_out has shape \(1, 4\); allowed: \(1, 3\)"):
        lrgf_free_run(torch.zeros(1, 4, 2), *args[:5], torch.zeros(1, 4))
    with pytest.raises(ValueError, match=r"n_linear=4; allowed: an integer from 0 to 3"):
        lrgf_free_run(torch.zeros(1, 4, 2), *args, n_linear=4)


# ---- linear neurons ----------------------------------------------------------------------------
def test_all_linear_network_is_a_sum_of_iir_filters() -> None:
    """With every neuron linear, eq. (6) is y = sum_i c_i H_i(q) w_i u: scipy's lfilter is the
    oracle, and the activation's g1, g2 play no part."""
    net = LRGF(2, 3, 2, 1, n_linear=3, seed=3).double()
    with torch.no_grad():
        net.g1.fill_(5.0)
        net.g2_raw.fill_(-3.0)
    u = np.random.default_rng(2).normal(size=(200, 2))
    num, den = (t.detach().numpy() for t in net.filter_coefficients())
    s = u @ net.weight_in.detach().numpy().T
    c = net.weight_out.detach().numpy()[0]
    oracle = sum(c[i] * sps.lfilter(num[i], np.r_[1.0, den[i]], s[:, i]) for i in range(3))
    np.testing.assert_allclose(net.predict(u)[:, 0], oracle, rtol=0, atol=1e-12)


def test_linear_neuron_extrapolates_where_tanh_neurons_saturate() -> None:
    """A linear neuron's output grows with its input without bound; a tanh neuron's does not."""
    z = np.linspace(-50.0, 50.0, 11)[:, None].repeat(2, axis=1)
    h = lrgf_activation(z, np.zeros(2), np.ones(2), n_linear=1)
    np.testing.assert_array_equal(h[:, 1], z[:, 1])
    assert np.all(np.abs(h[:, 0]) <= 1.0)


def test_linear_neurons_stream_save_and_refuse_bad_counts(tmp_path) -> None:
    net = LRGF(2, 3, 2, 1, n_linear=2, initial_state="steady", steady_window=5, seed=4).double()
    u = np.random.default_rng(0).normal(size=(120, 2))
    st = LRGFStepper(net)
    y_stream = np.stack([st.step(row) for row in u])
    np.testing.assert_allclose(y_stream, net.predict(u), rtol=0, atol=1e-10)
    config, state = export_module(net)
    assert config["n_linear"] == 2
    np.testing.assert_array_equal(build_module(config, state).predict(u), net.predict(u))
    old = {k: v for k, v in config.items() if k != "n_linear"}  # saved before n_linear existed
    assert build_module(old, state).n_linear == 0
    for bad in (-1, 4, 1.5, True):
        with pytest.raises(ValueError, match=rf"n_linear={bad!r}; allowed: an integer from 0 to"):
            LRGF(2, 3, 2, n_linear=bad)
