"""Parameters and variable names of the FCC converter model (the FCC model specification,
fcc-model.md, §1 and §2.9).

Every number of the model lives in :class:`FCCParams`, one field per row of the specification's §2.9
table, with its unit in the field comment. The nominal inputs are in :data:`NOMINAL_INPUTS`.

Departures from the table, each deliberate:

* ``V_rx_sp_m3`` is ``W_rx0_kg / rho_b0`` exactly (66.6667 m³): the table's rounded 66.667 says
  "= W_rx,0/ρ_b,0 exactly", and the rounded value would give a 40 000.2 kg set point.
* ``K_w1``/``K_w2`` are the table's formula ``416.6667 / (600·0.5^1.5)`` (1.964186) rather than the
  rounded 1.96419, so that the nominal crest is 0.5 m exactly and W_1 = W_2 = 90 000 kg, as in the
  verification run (the golden reference data's ``meta.json``).
* The nominal valve command is 416.6667 kg/s (the golden data's value; the table rounds to 416.667).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import NamedTuple

import numpy as np


class Measurement(NamedTuple):
    """One channel of the paper's Table 1."""

    name: str
    unit: str
    description: str
    noise_std: float  # white measurement noise std in ``unit`` (R_ar: relative, see noise_relative)
    noise_relative: bool = False


#: The eight measurements of the paper's Table 1, in observation order.
MEASUREMENTS: tuple[Measurement, ...] = (
    Measurement("R_ar", "t/h", "air flow rate to the regenerator", 0.005, True),
    Measurement("T_ar", "°C", "air temperature after the main blower", 0.3),
    Measurement("T_fp", "°C", "feed temperature at the riser entrance", 0.3),
    Measurement("T_rx", "°C", "temperature of the cracking mixture at the riser outlet", 0.3),
    Measurement("T_rg1", "°C", "regenerator first-stage dense-phase temperature", 0.3),
    Measurement("T_rg2", "°C", "regenerator second-stage dense-phase temperature", 0.3),
    Measurement("T_d1", "°C", "regenerator first-stage dilute-phase temperature", 0.5),
    Measurement("T_dg", "°C", "general dilute-phase temperature", 0.5),
)
MEASUREMENT_NAMES: tuple[str, ...] = tuple(m.name for m in MEASUREMENTS)

#: State vector order (spec §1.3): kg, kg/kg, °C.
STATE_NAMES: tuple[str, ...] = (
    "W_rx",  # kg, reactor/stripper catalyst holdup
    "C_sc",  # kg/kg, coke on spent catalyst
    "W1",  # kg, stage-1 dense-bed holdup
    "C1",  # kg/kg, stage-1 coke
    "T1",  # °C, stage-1 temperature (= T_rg1)
    "W2",  # kg, stage-2 dense-bed holdup
    "C2",  # kg/kg, stage-2 coke (= coke on regenerated catalyst)
    "T2",  # °C, stage-2 temperature (= T_rg2)
    "W_sp",  # kg, regenerated-catalyst well/standpipe inventory
    "T_d1",  # °C, stage-1 dilute phase
    "T_dg",  # °C, general dilute phase
)
STATE_UNITS: tuple[str, ...] = (
    "kg",
    "kg/kg",
    "kg",
    "kg/kg",
    "°C",
    "kg",
    "kg/kg",
    "°C",
    "kg",
    "°C",
    "°C",
)

#: Input vector order (spec §1.2).
INPUT_NAMES: tuple[str, ...] = (
    "u_F",  # kg/s, regenerated-catalyst slide-valve command (flow-equivalent opening)
    "R_ar",  # t/h, combustion air
    "T_ar",  # °C, air temperature
    "T_fp",  # °C, feed temperature
    "F_feed",  # kg/s, feed rate
    "f_coke",  # -, feed coking factor
)
INPUT_UNITS: tuple[str, ...] = ("kg/s", "t/h", "°C", "°C", "kg/s", "-")

NOMINAL_INPUTS: np.ndarray = np.array([416.6667, 148.4, 200.0, 230.0, 61.111, 1.0])
NOMINAL_INPUTS.flags.writeable = False

N_STATES = len(STATE_NAMES)
N_INPUTS = len(INPUT_NAMES)
N_MEASUREMENTS = len(MEASUREMENTS)


@dataclass(frozen=True, slots=True)
class FCCParams:
    """Physical constants of the converter (spec §2.9). Units in the comments.

    In batch simulation any field may be given per episode; the compiled kernels take the packed
    array from :meth:`as_array`.
    """

    # riser
    cp_c: float = 1.09  # kJ/kg/K, catalyst heat capacity
    cp_fe: float = 2.9  # kJ/kg/K, feed (effective liquid/vapour)
    dH_v: float = 200.0  # kJ/kg, gas-oil vaporisation
    dH_cr: float = 450.0  # kJ/kg converted, cracking (endothermic)
    E_cr: float = 60.0  # kJ/mol, cracking activation energy
    A_cr: float = 4290.0  # -, cracking pre-exponential (X = 0.75 at nominal)
    a_c: float = 1.0  # 1/wt%, catalyst deactivation by coke
    y_ccr: float = 0.015  # -, Conradson-carbon coke yield
    y_cat: float = 0.0417  # -, catalytic coke yield at g = g_0
    n_y: float = 0.6  # -, exponent of catalytic coke on severity
    g_0: float = 3.0  # -, reference severity X/(1-X)
    W_rx0_kg: float = 40_000.0  # kg, contact-time reference holdup (not changed by faults)
    # reactor / stripper
    tau_lc_s: float = 120.0  # s, reactor level P-loop time constant
    V_rx_sp_m3: float = 40_000.0 / 600.0  # m³, reactor holdup set point volume (fault f4)
    rho_b: float = 600.0  # kg/m³, catalyst bed and standpipe density (fault f1)
    dT_strip_C: float = 8.0  # °C, stripper temperature drop
    # weirs, well, slide valve
    A_1_m2: float = 40.0  # m², stage-1 bed area
    A_2_m2: float = 40.0  # m², stage-2 bed area
    h_w1_m: float = 3.25  # m, weir height stage 1
    h_w2_m: float = 3.25  # m, weir height stage 2
    K_w1: float = 416.6667 / (600.0 * 0.5**1.5)  # m^1.5/s, weir constant stage 1 (fault f2)
    K_w2: float = 416.6667 / (600.0 * 0.5**1.5)  # m^1.5/s, weir constant stage 2 (fault f2)
    beta_sv: float = 0.3  # -, share of valve ΔP from the well head; 0 = flow mode
    rho_b0: float = 600.0  # kg/m³, valve-law reference density (fixed)
    W_sp0_kg: float = 30_000.0  # kg, valve-law reference well inventory (fixed)
    # regenerator dense beds
    k_cb: float = 1.06e8  # 1/s/bar, coke burning pre-exponential
    E_cb: float = 150.0  # kJ/mol
    P_bar: float = 2.5  # bar abs, regenerator pressure
    w_H: float = 0.07  # -, hydrogen mass fraction of coke
    k_sigma: float = 2.68  # -, CO2/CO ratio constant (fault f3)
    E_sigma: float = 40.0  # kJ/mol
    T_sigma_ref_K: float = 958.15  # K (685 °C)
    alpha1: float = 0.815  # -, share of air to stage 1
    M_air: float = 28.96  # kg/kmol
    cp_air: float = 31.9  # kJ/kmol/K
    UA_1: float = 2.0  # kW/K, stage-1 heat loss
    UA_2: float = 2.0  # kW/K, stage-2 heat loss
    T_amb_C: float = 25.0  # °C
    h_C_CO2: float = 32_790.0  # kJ/kg C burnt to CO2
    h_C_CO: float = 9_210.0  # kJ/kg C burnt to CO
    h_H_H2O: float = 119_950.0  # kJ/kg H burnt to H2O(g)
    # dilute phases
    dH_CO: float = 283_000.0  # kJ/kmol, CO + ½O2 -> CO2
    cp_g: float = 33.5  # kJ/kmol/K, flue gas
    M_d1_kg: float = 10_000.0  # kg catalyst equivalent, stage-1 dilute phase incl. cyclones
    M_dg_kg: float = 15_000.0  # kg catalyst equivalent, general dilute phase
    F_ent1: float = 30.0  # kg/s, entrainment into d1, returned to stage 1
    F_ent2: float = 30.0  # kg/s, entrainment into dg, returned to stage 2
    eta1: float = 0.48  # -, afterburn efficiency d1
    eta_g: float = 0.54  # -, afterburn efficiency dg
    E_ab: float = 80.0  # kJ/mol, afterburn activation energy
    T_ab_ref_K: float = 973.0  # K
    UA_d1: float = 1.0  # kW/K
    UA_dg: float = 1.5  # kW/K
    R_gas: float = 8.314e-3  # kJ/mol/K

    def as_array(self) -> np.ndarray:
        """Pack the fields in declaration order (the compiled kernels' layout)."""
        return np.array([getattr(self, f) for f in PARAM_FIELDS], dtype=np.float64)

    def replace(self, **changes: float) -> FCCParams:
        """A copy with some fields changed (unknown names raise ValueError)."""
        unknown = sorted(set(changes) - set(PARAM_FIELDS))
        if unknown:
            raise ValueError(f"Unknown FCCParams field(s) {unknown}. Allowed: {list(PARAM_FIELDS)}")
        values = {f: getattr(self, f) for f in PARAM_FIELDS}
        values.update(changes)
        return FCCParams(**values)


PARAM_FIELDS: tuple[str, ...] = tuple(f.name for f in fields(FCCParams))
PARAM_INDEX: dict[str, int] = {name: i for i, name in enumerate(PARAM_FIELDS)}
