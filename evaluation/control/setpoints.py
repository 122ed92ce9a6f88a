"""The best fixed set points of ``FCC-control-v0`` for a plant: a steady-state optimisation.

Under the regulatory layer's integral action the plant settles where T_rx and T_rg1 equal their
set points, so choosing the set points is choosing the steady state the valve and the air hold.
:func:`best_setpoints` searches that steady state over the manipulated variables (u_F, R_ar)
within the actuator limits, scoring each by the control task's own reward per hour
(:func:`fcc_env.control_task.reward_terms` at ``dt = 3600 s``: margin and penalties, each
formula once), and returns the set points it implies. The set points must lie in the range an agent
may ask for (:data:`fcc_env.regulatory.SETPOINT_RANGES`).

The steady state keeps the plant's catalyst inventory: a fault that moves catalyst (f1's denser
catalyst, f4's larger reactor holdup) takes it from the regenerated-catalyst well, so the well
inventory is solved for with the total fixed at the healthy plant's (``brentq``), not held at
its nominal 30 t as :func:`fcc_env.physics.steady_state` holds it.

Search: differential evolution over the actuator box (``scipy.optimize.differential_evolution``,
seeded, so deterministic); set points outside their range cost an exterior penalty. The margin
has more than one local optimum and is flat along the riser-temperature limit (two optima
0.16 % apart), so a local search is not enough and the optimum is known to about 0.2 %.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import optimize

from fcc_env.control_task import EconomicReward, reward_terms
from fcc_env.params import NOMINAL_INPUTS, FCCParams
from fcc_env.physics import rhs_aux, steady_state
from fcc_env.regulatory import ACTUATOR_LIMITS, SETPOINT_RANGES
from fcc_env.scenarios import EpisodeFault

__all__ = [
    "OperatingPoint",
    "best_setpoints",
    "correctable_loops",
    "operating_point",
    "steady_operation",
    "total_inventory_kg",
]

# holdups in the state (spec §1): reactor, stage 1, stage 2, well
_HOLDUPS = (0, 2, 5, 8)
#: °C a loop's set point needs inside its range, on both sides, for a supervisor to correct it
MIN_ROOM_C = 2.0
#: USD/h per °C of set point outside its range in the search (steep next to any margin slope)
_RANGE_PENALTY_USD_PER_C_H = 1e4


@dataclass(frozen=True)
class OperatingPoint:
    """A steady operating point: the set points, the manipulated variables that hold them, and
    the reward per hour there (USD/h, its terms as :func:`reward_terms` names them)."""

    T_rx_sp: float
    T_rg1_sp: float
    u_F: float
    R_ar: float
    reward_usd_per_h: float
    terms_usd_per_h: dict[str, float]
    #: how far (°C, summed) the set points lie outside the range an agent may ask for
    range_excess_C: float = 0.0

    @property
    def setpoints(self) -> np.ndarray:
        return np.array([self.T_rx_sp, self.T_rg1_sp])


@lru_cache(maxsize=1)
def total_inventory_kg() -> float:
    """The healthy plant's catalyst inventory (reactor, both beds, well) at its steady state."""
    return float(steady_state()[list(_HOLDUPS)].sum())


def steady_operation(params: FCCParams, u_F: float, R_ar: float) -> np.ndarray:
    """The steady state at valve ``u_F`` (kg/s) and air ``R_ar`` (t/h), nominal feed and air and
    feed temperatures, with the healthy plant's total catalyst inventory."""
    u = NOMINAL_INPUTS.copy()
    u[0], u[1] = u_F, R_ar
    total = total_inventory_kg()

    def excess(w_sp: float) -> float:
        return float(steady_state(params, u, w_sp)[list(_HOLDUPS)].sum()) - total

    w_sp = optimize.brentq(excess, 1_000.0, 200_000.0, xtol=1.0)
    return steady_state(params, u, w_sp)


def operating_point(
    params: FCCParams,
    z: np.ndarray,
    economics: EconomicReward,
    reading_offset_C: tuple[float, float] = (0.0, 0.0),
) -> OperatingPoint | None:
    """The steady operating point at ``z = (u_F, R_ar)``, or None where there is none.

    ``reading_offset_C``: how far the loops' transmitters (T_rx, T_rg1) read above the true
    temperatures (a sensor bias): the set points that hold the point are the true temperatures
    plus it, and the range an agent may ask for applies to them (it is the loop's reading the
    regulatory layer compares with its set point)."""
    u_F, R_ar = (float(v) for v in z)
    try:
        x = steady_operation(params, u_F, R_ar)
    except (ValueError, RuntimeError):  # no steady state there (the root solvers failed)
        return None
    u = NOMINAL_INPUTS.copy()
    u[0], u[1] = u_F, R_ar
    aux = rhs_aux(x, u, params)
    setpoints = {
        "T_rx_sp": aux["T_rx"] + float(reading_offset_C[0]),
        "T_rg1_sp": float(x[4]) + float(reading_offset_C[1]),
    }
    if not np.all(np.isfinite(x)):
        return None
    excess = sum(
        max(0.0, SETPOINT_RANGES[k].low - v, v - SETPOINT_RANGES[k].high)
        for k, v in setpoints.items()
    )
    # a steady state at an actuator limit is held by a saturated loop (no authority left)
    at_limit = bool(np.isclose([[u_F, u_F], [R_ar, R_ar]], ACTUATOR_LIMITS, rtol=1e-6).any())
    info = {**aux, "state": x, "inputs": u, "controller_saturated": at_limit}
    terms = reward_terms(info, False, economics, 3600.0)
    return OperatingPoint(
        setpoints["T_rx_sp"],
        setpoints["T_rg1_sp"],
        u_F,
        R_ar,
        math.fsum(terms.values()),
        terms,
        excess,
    )


def best_setpoints(
    fault: EpisodeFault | None = None,
    economics: EconomicReward | None = None,
    params: FCCParams | None = None,
    *,
    reading_offset_C: tuple[float, float] = (0.0, 0.0),
    limits: np.ndarray | None = None,
) -> OperatingPoint:
    """The steady set points with the highest reward per hour for the plant ``params`` (default:
    the declared plant) with ``fault`` at its full size (``None``: healthy).

    ``reading_offset_C``: the loops' transmitters read this much high (°C, T_rx and T_rg1;
    :func:`operating_point`). ``limits``: the reachable ``(u_F, R_ar)`` box, shape ``(2, 2)``
    (default :data:`~fcc_env.regulatory.ACTUATOR_LIMITS`): a weaker blower lowers the air's
    ceiling, a stuck valve pins ``u_F`` (:mod:`evaluation.control.fault_oracle`)."""
    economics = EconomicReward() if economics is None else economics
    p = FCCParams() if params is None else params
    if fault is not None:
        p = fault.faulty_params(p)
    box = ACTUATOR_LIMITS if limits is None else np.asarray(limits, dtype=np.float64)
    if box.shape != (2, 2) or not np.all(box[:, 0] < box[:, 1]):
        raise ValueError(f"limits={box.tolist()}: allowed: [[u_F low, high], [R_ar low, high]]")
    lo, hi = box[:, 0], box[:, 1]

    def cost(z: np.ndarray) -> float:
        z = np.clip(z, lo, hi)
        point = operating_point(p, z, economics, reading_offset_C)
        if point is None:
            return math.inf
        # an exterior penalty, not a wall: the optimum often lies on the range's edge
        return -point.reward_usd_per_h + _RANGE_PENALTY_USD_PER_C_H * point.range_excess_C

    # the margin has more than one local optimum along the riser-temperature limit (more
    # circulation and a cooler bed, or less and a hotter one): a global search (differential
    # evolution, seeded)
    res = optimize.differential_evolution(
        cost,
        list(zip(lo, hi, strict=True)),
        seed=0,
        popsize=10,
        maxiter=30,
        tol=1e-7,
        polish=False,  # the penalty's kink and the infeasible corners defeat a gradient polish
    )
    if not np.isfinite(res.fun):  # pragma: no cover - the declared plant always has one
        raise ValueError(f"no steady state with set points in range for fault {fault}")
    z = np.clip(res.x, lo, hi)
    point = operating_point(p, z, economics, reading_offset_C)
    assert point is not None
    return point


def correctable_loops(setpoints: np.ndarray, min_room_C: float = MIN_ROOM_C) -> np.ndarray:
    """Which loops (T_rx, T_rg1) a supervisor can correct through their set points about
    ``setpoints`` (°C): those with ``min_room_C`` inside the range on both sides. At the healthy
    optimum the riser's set point is on its range's top (545 °C): a correction upwards is
    clipped, so a loop rebuilt there could only push one way (on a stuck T_rx transmitter that
    tripped 16 of 20 validation episodes, against 13 of 20 left alone: lab/control-catalogue.md).
    """
    names = ("T_rx_sp", "T_rg1_sp")
    low = np.array([SETPOINT_RANGES[n].low for n in names])
    high = np.array([SETPOINT_RANGES[n].high for n in names])
    sp = np.asarray(setpoints, dtype=np.float64)
    return (sp - low >= min_room_C) & (high - sp >= min_room_C)
