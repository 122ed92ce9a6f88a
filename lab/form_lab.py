"""The modelling loop's form search on effects outside the library (issue 46): lab/form_lab.md.

``PYTHONPATH=. python lab/form_lab.py dev|val|clean|timing [--seeds 1000,1001]``

* ``dev``: effects used while building the search (seeds 1000+);
* ``val``: the four held-out effects of tests/evaluation/discover/test_discover_forms.py
  (seeds 5000+), run once at the end;
* ``new``: four more effects outside the library, built to check generality (seeds 5000+), never
  tuned on;
* ``clean``: clean data with ``forms="always"`` (the search forced to run): nothing may be proposed;
* ``timing``: the loop on a 4-episode dataset, CPU time (the machine is shared: wall time is not
  a measure here).

None of these effects is in :mod:`fcc_env.effects`: they are user ``d_state``/``measure`` hooks.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

import fcc_env
from evaluation import discover as d

N = 4000


class StateTerm:
    """A hidden term added to one state derivative: ``fn(x, u)`` in °C/s."""

    def __init__(self, name, fn):
        self.name, self.fn = name, fn

    def d_state(self, t, x, u, params):
        out = np.zeros_like(x)
        i, v = self.fn(x, u)
        out[..., i] = v
        return out


class Saturation:
    """A thermocouple reading that saturates: c + s·tanh((T − c)/s) on one channel."""

    def __init__(self, name, channel, c, s):
        self.name, self.j, self.c, self.s = name, fcc_env.MEASUREMENT_NAMES.index(channel), c, s

    def measure(self, t, y):
        out = np.array(y, dtype=float, copy=True)
        out[..., self.j] = self.c + self.s * np.tanh((out[..., self.j] - self.c) / self.s)
        return out


DEV = [
    StateTerm(
        "coupling: dT_rg1/dt += 2e-4·(T_rg2 − T_rg1)",
        lambda x, u: (4, 2e-4 * (x[..., 7] - x[..., 4])),
    ),
    StateTerm(
        "quadratic loss: dT_rg2/dt −= 1e-5·(T_rg2 − 700)²",
        lambda x, u: (7, -1e-5 * (x[..., 7] - 700.0) ** 2),
    ),
    Saturation("saturation: T_d1 read as 698 + 8·tanh((T_d1 − 698)/8)", "T_d1", 698.0, 8.0),
    StateTerm(
        "product: dT_dg/dt += 2e-5·(R_ar − 148)·(T_dg − 700)",
        lambda x, u: (10, 2e-5 * (u[..., 1] - 148.0) * (x[..., 10] - 700.0)),
    ),
]
VAL = [
    StateTerm(
        "quadratic loss: dT_rg1/dt −= 2e-5·(T_rg1 − 660)²",
        lambda x, u: (4, -2e-5 * (x[..., 4] - 660.0) ** 2),
    ),
    StateTerm(
        "cross-coupling: dT_d1/dt += 2e-4·(T_dg − T_d1)",
        lambda x, u: (9, 2e-4 * (x[..., 10] - x[..., 9])),
    ),
    Saturation("saturation: T_rg2 read as 716 + 10·tanh((T_rg2 − 716)/10)", "T_rg2", 716.0, 10.0),
    StateTerm(
        "product: dT_rg2/dt += 2e-5·(T_ar − 200)·(T_rg2 − 716)",
        lambda x, u: (7, 2e-5 * (u[..., 2] - 200.0) * (x[..., 7] - 716.0)),
    ),
]


class LaggedReading:
    """A channel read with another signal's first-order lag mixed in (a measurement hook with its
    own filter state, reset at t = 0): y[j] += g·(lag_tau(y[src]) − c)."""

    def __init__(self, name, channel, source, gain, tau_s, c, dt=10.0):
        self.name, self.g, self.c = name, gain, c
        self.j = fcc_env.MEASUREMENT_NAMES.index(channel)
        self.src = fcc_env.MEASUREMENT_NAMES.index(source)
        self.a = float(np.exp(-dt / tau_s))
        self.state = None

    def measure(self, t, y):
        out = np.array(y, dtype=float, copy=True)
        v = out[..., self.src]
        self.state = (
            v.copy() if t == 0 or self.state is None else self.a * self.state + (1 - self.a) * v
        )
        out[..., self.j] += self.g * (self.state - self.c)
        return out


#: Effects built for checking generality (issue 46, forms2): nothing was tuned on them.
NEW = [
    Saturation("saturation: T_dg read as 712 + 5·tanh((T_dg − 712)/5)", "T_dg", 712.0, 5.0),
    StateTerm(
        "exponential loss: dT_rg2/dt −= 2e-3·exp((T_rg2 − 716)/12)",
        lambda x, u: (7, -2e-3 * np.exp((x[..., 7] - 716.0) / 12.0)),
    ),
    LaggedReading(
        "lagged reading: T_rx += 0.6·(lag900s(T_ar) − 198)", "T_rx", "T_ar", 0.6, 900.0, 198.0
    ),
    StateTerm(
        "product: dT_d1/dt += 3e-5·(T_rg1 − 680)·(T_fp − 230)",
        lambda x, u: (9, 3e-5 * (x[..., 4] - 680.0) * (u[..., 3] - 230.0)),
    ),
]


def run_effect(eff, seed: int, forms: str = "auto", search=None) -> dict:
    data = d.from_batch(fcc_env.simulate_episodes([seed], N, plant_effects=[eff]))
    floor = d.heldout_rmse(d.from_batch(fcc_env.simulate_episodes([seed], N)))
    t0 = time.process_time()
    rep = d.discover(data, max_effects=3, forms=forms, form_search=search, plots=False).to_json()
    cpu = time.process_time() - t0
    gap = {c: rep["rmse_before"][c] - floor[c] for c in floor}
    ch = max(gap, key=gap.get)
    forms = [e for e in rep["effects"] if "equation" in e]
    ok = bool(forms) and rep["rmse_after"][ch] <= 1.3 * floor[ch]
    ok = ok and all(len(e["form"]["terms"]) <= 3 for e in forms)
    return {
        "effect": eff.name,
        "seed": seed,
        "channel": ch,
        "floor": round(floor[ch], 3),
        "before": round(rep["rmse_before"][ch], 3),
        "after": round(rep["rmse_after"][ch], 3),
        "ratio_to_floor": round(rep["rmse_after"][ch] / floor[ch], 3),
        "effects": [e.get("equation", {}).get("text", e["id"]) for e in rep["effects"]],
        "shapes": [e["equation"]["shapes"] for e in forms],
        "library_tried_first": [r["accepted"] for r in rep["rounds"] if r.get("kind") != "form"],
        "ok": ok,
        "cpu_s": round(cpu, 1),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("which", choices=["dev", "val", "new", "clean", "timing"])
    ap.add_argument("--seeds", default=None)
    ap.add_argument("--only", default=None, help="indices of the set's effects, e.g. 0,2")
    ap.add_argument("--forms", default="auto", choices=["auto", "always"])
    ap.add_argument("--exp", action="store_true", help="exp factors in the library too")
    ap.add_argument("--fixed-shapes", action="store_true", help="FormSearch(fit_shapes=False)")
    a = ap.parse_args()
    if a.which in ("dev", "val", "new"):
        effects = {"dev": DEV, "val": VAL, "new": NEW}[a.which]
        if a.only is not None:
            effects = [effects[int(i)] for i in a.only.split(",")]
        seeds = [int(s) for s in (a.seeds or ("1000" if a.which == "dev" else "5000")).split(",")]
        for seed in seeds:
            for eff in effects:
                search = d.FormSearch(
                    library=d.TermLibrary(functions=("lin", "sq", "tanh", *("exp",) * a.exp)),
                    fit_shapes=not a.fixed_shapes,
                )
                out = run_effect(eff, seed, a.forms, search)
                print(json.dumps(out, ensure_ascii=False), flush=True)
    elif a.which == "clean":
        seeds = [int(s) for s in (a.seeds or "1000,1001,1002,1003,1004").split(",")]
        for seed in seeds:
            data = d.from_batch(fcc_env.simulate_episodes([seed], N))
            t0 = time.process_time()
            rep = d.discover(data, max_effects=1, forms="always", plots=False).to_json()
            fr = [r for r in rep["rounds"] if r.get("kind") == "form"]
            best = fr[0]["candidates"][:1] if fr and fr[0]["candidates"] else []
            print(
                json.dumps(
                    {
                        "seed": seed,
                        "effects": [e["id"] for e in rep["effects"]],
                        "best_form_tested": best,
                        "cpu_s": round(time.process_time() - t0, 1),
                    },
                    ensure_ascii=False,
                ),
                flush=True,
            )
    else:
        seeds = [int(s) for s in (a.seeds or "1000,1001,1002,1003").split(",")]
        data = d.from_batch(fcc_env.simulate_episodes(seeds, N, plant_effects=[DEV[0]]))
        t0, w0 = time.process_time(), time.perf_counter()
        rep = d.discover(data, max_effects=3, plots=False, progress=True)
        print(
            json.dumps(
                {
                    "episodes": len(seeds),
                    "samples": N,
                    "cpu_s": round(time.process_time() - t0, 1),
                    "wall_s": round(time.perf_counter() - w0, 1),
                    "effects": [e.equation["text"] if e.equation else e.id for e in rep.effects],
                },
                ensure_ascii=False,
            )
        )


if __name__ == "__main__":
    main()
