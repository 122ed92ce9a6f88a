"""Linear analysis of the closed loop: the one-sample map of plant and controllers, its steady
state and the eigenvalues of its Jacobian, with damping and time constants (issue 31's proof).

The closed loop is a sampled-data system: plant state x (11) and controller state c (4) advance
together once per sample, z_{k+1} = F(z_k) with the set points held and the operating program
at nominal (noise-free; the controllers read the float64 measurement). It is locally stable at
a steady state z* when every eigenvalue λ of ∂F/∂z (central differences) lies inside the unit
circle (the conserved catalyst inventory's λ = 1 is set aside, see
:func:`_without_inventory_mode`). Each λ maps to a continuous-time s = ln(λ)/Ts, with damping ζ = −Re s/|s| and time
constant 1/|Re s| — the quantities ``control.damp`` reports for a discrete system.

Run ``python -m fcc_env.closed_loop_analysis`` for the table of the docs' closed-loop page
(nominal, each fault at its largest allowed size, the 16 corners of the ``uncertain`` draw).
"""

from __future__ import annotations

import argparse
import itertools
from dataclasses import dataclass

import numpy as np
from scipy.optimize import root

from fcc_common.invocation import command_parser, run_command
from fcc_env.integrator import step_kernel
from fcc_env.params import N_STATES, NOMINAL_INPUTS, FCCParams
from fcc_env.physics import as_param_array, measure_core
from fcc_env.plant import DEFAULT_SAMPLE_TIME_S, PlantConfig
from fcc_env.regulatory import (
    CONTROLLER_STATE_SIZE,
    RegulatoryLayer,
    apply_controller_outputs,
    controller_update,
)
from fcc_env.scenarios import FAULTS, EpisodeFault
from fcc_env.uncertainty import GROUP_FIELDS, PlantUncertainty

__all__ = ["StabilityCase", "closed_loop_eigenvalues", "stability_cases", "stability_table"]

_NO_FAULT = np.array([-1], dtype=np.int64)
_ONE = np.ones(1)


def closed_loop_map(
    z: np.ndarray, p: np.ndarray, layer: RegulatoryLayer, setpoints: np.ndarray, ts: float
) -> np.ndarray:
    """z = [x (11), c (4)] after one noise-free sample with set points ``setpoints``."""
    x = np.array(z[:N_STATES], dtype=np.float64)
    c = np.array(z[N_STATES:], dtype=np.float64)
    gains = layer.gains(ts)
    u = NOMINAL_INPUTS.copy()
    apply_controller_outputs(u, c, gains)
    y = np.empty(8)
    measure_core(x, u, p, y)
    step_kernel(x, u, p, _NO_FAULT, _ONE, ts, 1)
    controller_update(c, setpoints, y, gains)
    return np.concatenate([x, c])


def closed_loop_steady_state(
    p: np.ndarray, layer: RegulatoryLayer, setpoints: np.ndarray, ts: float, x0: np.ndarray
) -> np.ndarray:
    """The fixed point of :func:`closed_loop_map`: simulated towards it, then polished by a root
    solver (scaled so kg, kg/kg and °C weigh alike)."""
    z = np.concatenate([x0, [NOMINAL_INPUTS[0], 0.0, NOMINAL_INPUTS[1], 0.0]])
    for _ in range(6000):
        z = closed_loop_map(z, p, layer, setpoints, ts)
    scale = np.maximum(np.abs(z), 1e-3)
    sol = root(
        lambda w: (closed_loop_map(w * scale, p, layer, setpoints, ts) - w * scale) / scale,
        z / scale,
        method="hybr",
    )
    return sol.x * scale


def closed_loop_eigenvalues(
    p: np.ndarray, layer: RegulatoryLayer, setpoints: np.ndarray, ts: float, z: np.ndarray
) -> np.ndarray:
    """Eigenvalues of ∂F/∂z at ``z`` (central differences, relative steps)."""
    n = z.shape[0]
    J = np.empty((n, n))
    for j in range(n):
        h = 1e-6 * max(abs(z[j]), 1e-3)
        zp, zm = z.copy(), z.copy()
        zp[j] += h
        zm[j] -= h
        J[:, j] = (
            closed_loop_map(zp, p, layer, setpoints, ts)
            - closed_loop_map(zm, p, layer, setpoints, ts)
        ) / (2 * h)
    return _without_inventory_mode(J)


#: The catalyst masses of the state (W_rx, W1, W2, W_sp): no catalyst enters or leaves the loop.
_INVENTORY = np.zeros(N_STATES + CONTROLLER_STATE_SIZE)
_INVENTORY[[0, 2, 5, 8]] = 1.0


def _without_inventory_mode(J: np.ndarray) -> np.ndarray:
    """Eigenvalues of J without the conserved catalyst inventory's λ = 1.

    The total catalyst mass is an exact invariant (RK4 keeps linear invariants), so J has the
    left eigenvector of the masses with λ = 1 in open and closed loop alike: a neutral
    direction (which inventory the unit holds), not an instability. Checked, then dropped.
    """
    drift = np.abs(_INVENTORY @ J - _INVENTORY).max()
    if drift > 1e-5:
        raise RuntimeError(f"the catalyst inventory is not conserved by the map (drift {drift:g})")
    lam = np.linalg.eigvals(J)
    return np.delete(lam, np.argmin(np.abs(lam - 1.0)))


@dataclass(frozen=True)
class StabilityCase:
    """One row of the stability table."""

    name: str
    max_abs_eigenvalue: float  # of the discrete map; < 1 is stable
    min_damping: float  # ζ of the least damped oscillatory mode (1.0 if none oscillates)
    slowest_time_constant_min: float
    u_F_kg_s: float  # steady valve command
    R_ar_t_h: float  # steady air

    @property
    def stable(self) -> bool:
        return self.max_abs_eigenvalue < 1.0


def _case(name: str, params: FCCParams, layer: RegulatoryLayer, ts: float) -> StabilityCase:
    config = PlantConfig(regulatory=layer, sample_time_s=ts)
    setpoints = config.initial_setpoints()  # the nominal plant's: the unit's set points
    p = as_param_array(params)
    z = closed_loop_steady_state(p, layer, setpoints, ts, config.initial_state())
    lam = closed_loop_eigenvalues(p, layer, setpoints, ts, z)
    s = np.log(lam.astype(complex)) / ts
    osc = np.abs(s.imag) > 1e-12
    damping = -s.real[osc] / np.abs(s[osc])
    return StabilityCase(
        name=name,
        max_abs_eigenvalue=float(np.abs(lam).max()),
        min_damping=float(damping.min()) if damping.size else 1.0,
        slowest_time_constant_min=float(1.0 / np.abs(s.real).min() / 60.0),
        u_F_kg_s=float(z[N_STATES]),
        R_ar_t_h=float(z[N_STATES + 2]),
    )


def stability_cases(
    layer: RegulatoryLayer | None = None, ts: float = DEFAULT_SAMPLE_TIME_S, corners: bool = True
) -> list[StabilityCase]:
    """Nominal, each registered fault at its largest allowed size, and (``corners``) the 16
    corners of the ``uncertain`` track's parameter draw (every group at ± its default
    half-range). A fault that scales no parameter (it acts on the measurement or actuator
    path only) leaves the linearised plant as it is and has no case of its own."""
    layer = layer or RegulatoryLayer()
    base = FCCParams()
    cases = [_case("nominal", base, layer, ts)]
    for sc, d in FAULTS.items():
        if d.parameters:
            plant = EpisodeFault(sc, 0, d.max_magnitude).faulty_params(base)
            cases.append(_case(f"{sc} at {d.max_magnitude:.0%}", plant, layer, ts))
    if corners:
        u = PlantUncertainty()
        groups = list(GROUP_FIELDS)
        for signs in itertools.product((-1, 1), repeat=len(groups)):
            changes: dict[str, float] = {}
            for g, sgn in zip(groups, signs, strict=True):
                half = getattr(u, g)
                for f in GROUP_FIELDS[g]:
                    mult = (1 + sgn * half) ** -2 if g == "valve" else 1 + sgn * half
                    changes[f] = getattr(base, f) * mult
            label = "uncertain " + " ".join(
                f"{g}{'+' if s > 0 else '−'}" for g, s in zip(groups, signs, strict=True)
            )
            cases.append(_case(label, base.replace(**changes), layer, ts))
    return cases


def stability_table(cases: list[StabilityCase]) -> str:
    """A Markdown table of :func:`stability_cases`."""
    lines = [
        "| plant | max abs eigenvalue | least damping ζ | slowest τ [min] | u_F [kg/s] | R_ar [t/h] |",
        "|---|---|---|---|---|---|",
    ]
    for c in cases:
        lines.append(
            f"| {c.name} | {c.max_abs_eigenvalue:.5f} | {c.min_damping:.3f} | "
            f"{c.slowest_time_constant_min:.1f} | {c.u_F_kg_s:.1f} | {c.R_ar_t_h:.2f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = command_parser(
        "fcc_env.closed_loop_analysis",
        "Eigenvalues of the linearised closed loop (plant + regulatory layer). Exits with 1 "
        "when a case is unstable.",
        (
            ("", "the table of the docs: nominal, each fault, the 16 uncertain corners"),
            ("--no-corners", "nominal and each fault only"),
        ),
    )
    ap.add_argument("--no-corners", action="store_true", help="skip the 16 uncertain corners")
    return run_command(ap, _analyse, argv)


def _analyse(args: argparse.Namespace) -> int:
    """The work of :func:`main`: its failures (and a Ctrl-C) are reported by :func:`run_command`."""
    cases = stability_cases(corners=not args.no_corners)
    print(stability_table(cases))
    return 0 if all(c.stable for c in cases) else 1


if __name__ == "__main__":
    raise SystemExit(main())
