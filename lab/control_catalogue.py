"""The value of information per fault class on FCC-control-v0's whole catalogue (issue 43 item 7).

Runs validation seeds (5000..) of ``gym.make("FCC-control-v0", catalogue="all")`` under three
policies: the best fixed set points of the healthy plant (the fault-blind policy of the table;
a PPO agent joins with ``--ppo``, lab/control-catalogue.md section 5), the
sensor-correcting supervisor (its frozen-reading check; no diagnoser) and the oracle
(:class:`evaluation.control.fault_oracle.FaultOracle`). Per episode it writes the drawn fault
and the three returns to ``--out`` (JSON lines); ``--report`` reads such files and prints the
table: per fault class, each policy's mean return, the value of information (oracle − fault-blind,
paired by episode) and what the supervisor captures (supervisor − fault-blind), each with its
95 % bootstrap interval.

    python lab/control_catalogue.py --first 5000 --n 100 --out /tmp/voi_a.jsonl
    python lab/control_catalogue.py --report /tmp/voi_a.jsonl /tmp/voi_b.jsonl
    python lab/control_catalogue.py --loop-sensors --first 5000 --n 20 --out /tmp/loop.jsonl
    python lab/control_catalogue.py --loop-sensors --diagnoser sensor-validation --first 5220 \
        --n 5 --out /tmp/loop_sv.jsonl

``--ppo DIR`` adds a saved PPO agent (``python -m evaluation.control.rl train --out DIR``; the
issue's fault-blind policy when trained on the same draws, e.g. ``--catalogue sensor``) as the
policy ``ppo``; the report then adds its columns, the supervisor's paired gain over it and
whether their intervals overlap.

    python lab/control_catalogue.py --loop-sensors --ppo /tmp/ppo_sensor --first 5300 --n 10 \
        --out /tmp/loop_ppo.jsonl

``--hybrid`` (with ``--ppo DIR``) adds ``ppo+sensor-correcting``: the same agent, overridden by
the sensor-correcting supervisor on the loops it judges faulty
(:mod:`evaluation.control.hybrid_policy`); the report then adds, per class, its mean, its and
the supervisor's paired gains over the agent, and whether each one's unpaired interval lies
above the agent's.

``--diagnoser NAME`` adds a fourth policy, ``sensor-correcting+NAME``: the same supervisor
with registered diagnoser NAME streamed in it (fitted on training seeds by
:func:`evaluation.control.sensor_policy.fit_sensor_diagnoser`); the report then adds its
columns and its paired gain over the supervisor without it. With ``--diagnoser-only`` that
policy's frozen-reading and residual checks are off (``sensor-correcting+NAME only``): what the
diagnosis alone judges.
"""

from __future__ import annotations

import argparse
import json
import time

import gymnasium as gym
import numpy as np

import fcc_env  # noqa: F401 (registers the envs)
from evaluation.control.policy_registry import make_policy
from evaluation.metrics.intervals import bootstrap_ci
from fcc_env.control_draws import LOOP_CHANNELS, FaultClass, fault_class

POLICIES = ("fixed", "sensor-correcting", "oracle")
#: ``--hybrid``: the agent overridden by the supervisor on its judged loops
HYBRID = "ppo+sensor-correcting"


#: ``--loop-sensors``: the sensor faults that reach the process, each at its default size and
#: onset (sample 2000), on both loop transmitters
LOOP_SENSOR_SCENARIOS = [
    (f"sensor-{kind}", ch) for kind in ("bias", "drift", "stuck") for ch in LOOP_CHANNELS
]


def run(
    first: int,
    n: int,
    out: str,
    steps: int = 3999,
    loop_sensors: bool = False,
    diagnoser: str | None = None,
    diagnoser_only: bool = False,
    ppo: str | None = None,
    hybrid: bool = False,
) -> None:
    policies = {name: make_policy(name) for name in POLICIES}
    if ppo:
        policies["ppo"] = make_policy("ppo", directory=ppo)
    if hybrid:
        if not ppo:
            raise ValueError("hybrid=True needs ppo=DIR: allowed: --hybrid with --ppo DIR")
        soft = policies["sensor-correcting"].soft_sensor  # one fit for both supervisors
        policies[HYBRID] = make_policy(HYBRID, directory=ppo, soft_sensor=soft)
    if diagnoser:
        # diagnosis only: the frozen and residual checks can never fire
        off = {"frozen_samples": 10**9, "limit_C": 1e9} if diagnoser_only else {}
        key = f"sensor-correcting+{diagnoser}" + (" only" if diagnoser_only else "")
        policies[key] = make_policy("sensor-correcting", diagnoser=diagnoser, **off)
    cases = LOOP_SENSOR_SCENARIOS if loop_sensors else [None]
    with open(out, "w") as f:
        for seed, case in ((s, c) for s in range(first, first + n) for c in cases):
            t0 = time.process_time()
            row: dict = {"seed": seed}
            for name, policy in policies.items():
                if case is None:
                    env = gym.make("FCC-control-v0", catalogue="all")
                else:
                    env = gym.make("FCC-control-v0", scenario=case[0], fault_channel=case[1])
                obs, info = env.reset(seed=seed)
                policy.reset(info)
                fault = env.unwrapped.plant.fault
                row.update(
                    scenario=fault.scenario,
                    channel=fault.channel,
                    magnitude=fault.magnitude,
                    onset=fault.onset,
                )
                total, tripped = 0.0, False
                for _ in range(steps):
                    obs, reward, terminated, truncated, info = env.step(policy.act(obs, info))
                    total += float(reward)
                    if terminated or truncated:
                        tripped = bool(terminated)
                        break
                row[name] = total
                row[name + "_trip"] = tripped
                env.close()
            row["cpu_s"] = round(time.process_time() - t0, 2)
            f.write(json.dumps(row) + "\n")
            f.flush()


def _ci(values) -> str:
    if len(values) < 2:
        return "n/a"
    iv = bootstrap_ci(list(values))
    return f"{iv.estimate:,.0f} [{iv.low:,.0f}, {iv.high:,.0f}]"


def report(paths: list[str]) -> None:
    by_seed: dict[tuple, dict] = {}
    for p in paths:  # an episode run twice (overlapping ranges) counts once
        for line in open(p):
            r = json.loads(line)
            by_seed.setdefault((r["seed"], r["scenario"], r["channel"]), r)
    rows = [by_seed[k] for k in sorted(by_seed)]
    groups: dict[str, list[dict]] = {c.value: [] for c in FaultClass}
    for r in rows:
        groups[fault_class(r["scenario"]).value].append(r)
    loop = [r for r in groups["sensor"] if r["channel"] in LOOP_CHANNELS]
    groups["sensor, loop channel"] = loop
    for kind in ("stuck", "bias", "drift"):
        for ch in LOOP_CHANNELS:
            groups[f"sensor-{kind} on {ch}"] = [
                r for r in loop if r["scenario"] == f"sensor-{kind}" and r["channel"] == ch
            ]
    groups["sensor, other channels"] = [
        r for r in groups["sensor"] if r["channel"] not in LOOP_CHANNELS
    ]
    for sc in ("valve-stiction", "valve-bias", "valve-stuck", "blower-capacity"):
        groups[sc] = [r for r in groups["actuator"] if r["scenario"] == sc]
    groups["all"] = rows
    print(
        "| class | n | fault-blind (best fixed) | oracle | sensor-correcting | value of "
        "information (oracle − blind) | captured (sensor-correcting − blind) | trips b/s/o |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name, g in groups.items():
        if not g:
            continue
        blind = np.array([r["fixed"] for r in g])
        orc = np.array([r["oracle"] for r in g])
        sup = np.array([r["sensor-correcting"] for r in g])
        trips = "/".join(str(sum(r[p + "_trip"] for r in g)) for p in POLICIES)
        print(
            f"| {name} | {len(g)} | {_ci(blind)} | {_ci(orc)} | {_ci(sup)} | "
            f"{_ci(orc - blind)} | {_ci(sup - blind)} | {trips} |"
        )
    extra = sorted({k for r in rows for k in r if k.startswith("sensor-correcting+")})
    for key in (k for k in extra if not k.endswith("_trip")):
        print(
            f"\n| class | n | {key} | captured ({key} − blind) | {key} − sensor-correcting "
            "| trips |"
        )
        print("|---|---|---|---|---|---|")
        for name, g in groups.items():
            g = [r for r in g if key in r]
            if not g:
                continue
            blind = np.array([r["fixed"] for r in g])
            sup = np.array([r["sensor-correcting"] for r in g])
            diag = np.array([r[key] for r in g])
            trips = sum(r[key + "_trip"] for r in g)
            print(
                f"| {name} | {len(g)} | {_ci(diag)} | {_ci(diag - blind)} | {_ci(diag - sup)} "
                f"| {trips} |"
            )
    if any("ppo" in r for r in rows):
        _report_ppo(groups)
    if any(HYBRID in r for r in rows):
        _report_hybrid(groups)
    print(f"\n{len(rows)} episodes, {sum(r['cpu_s'] for r in rows):.0f} CPU s")


def _report_ppo(groups: dict[str, list[dict]]) -> None:
    """The PPO agent beside the best fixed set points and the sensor-correcting supervisor:
    means, the supervisor's paired gain over the agent, and whether the unpaired intervals of
    the two overlap (the issue's goal: a diagnosis-driven policy above the best fault-blind
    one, intervals apart)."""
    print(
        "\n| class | n | ppo | fixed | sensor-correcting | ppo − fixed | sensor-correcting − ppo "
        "| intervals apart | trips ppo |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name, g in groups.items():
        g = [r for r in g if "ppo" in r]
        if len(g) < 2:
            continue
        agent = np.array([r["ppo"] for r in g])
        blind = np.array([r["fixed"] for r in g])
        sup = np.array([r["sensor-correcting"] for r in g])
        a, c = bootstrap_ci(list(agent)), bootstrap_ci(list(sup))
        apart = "yes" if c.low > a.high else "no"
        trips = sum(r["ppo_trip"] for r in g)
        print(
            f"| {name} | {len(g)} | {_ci(agent)} | {_ci(blind)} | {_ci(sup)} | "
            f"{_ci(agent - blind)} | {_ci(sup - agent)} | {apart} | {trips} |"
        )


def _report_hybrid(groups: dict[str, list[dict]]) -> None:
    """The hybrid beside the agent and the supervisor: means, each one's paired gain over the
    agent, whether its unpaired interval lies above the agent's (the goal's "apart")."""
    print(
        f"\n| class | n | ppo | sensor-correcting | {HYBRID} | {HYBRID} − ppo | apart "
        "| sensor-correcting − ppo | apart | trips ppo/s-c/hybrid |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, g in groups.items():
        g = [r for r in g if HYBRID in r]
        if len(g) < 2:
            continue
        agent = np.array([r["ppo"] for r in g])
        sup = np.array([r["sensor-correcting"] for r in g])
        hyb = np.array([r[HYBRID] for r in g])
        a, c, h = (bootstrap_ci(list(x)) for x in (agent, sup, hyb))
        trips = "/".join(
            str(sum(r[k + "_trip"] for r in g)) for k in ("ppo", "sensor-correcting", HYBRID)
        )
        print(
            f"| {name} | {len(g)} | {_ci(agent)} | {_ci(sup)} | {_ci(hyb)} | {_ci(hyb - agent)} "
            f"| {'yes' if h.low > a.high else 'no'} | {_ci(sup - agent)} "
            f"| {'yes' if c.low > a.high else 'no'} | {trips} |"
        )


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--first", type=int, default=5000)
    ap.add_argument("--n", type=int, default=50)
    ap.add_argument("--out", default="/tmp/control_catalogue.jsonl")
    ap.add_argument("--report", nargs="*")
    ap.add_argument(
        "--loop-sensors",
        action="store_true",
        help="the six loop-sensor faults at their default size on each seed, not the draws",
    )
    ap.add_argument(
        "--diagnoser",
        default=None,
        help="a registered diagnoser streamed in a fourth policy, sensor-correcting+NAME",
    )
    ap.add_argument(
        "--diagnoser-only",
        action="store_true",
        help="the fourth policy judges by the diagnosis alone (frozen and residual checks off)",
    )
    ap.add_argument("--ppo", default=None, help="a saved PPO agent's directory: policy ppo")
    ap.add_argument("--hybrid", action="store_true", help=f"with --ppo: the policy {HYBRID} too")
    a = ap.parse_args()
    if a.hybrid and not a.ppo:
        raise SystemExit("--hybrid needs --ppo DIR (the agent it overrides)")
    if a.report:
        report(a.report)
    else:
        if a.first < 5000:
            raise SystemExit(f"--first {a.first}: validation seeds only (5000..)")
        run(
            a.first,
            a.n,
            a.out,
            loop_sensors=a.loop_sensors,
            diagnoser=a.diagnoser,
            diagnoser_only=a.diagnoser_only,
            ppo=a.ppo,
            hybrid=a.hybrid,
        )
