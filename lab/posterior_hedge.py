"""The posterior supervisor's hedge on f2/f4 (issue 42): the posterior it sees, and what any
threshold rule on it could do.

``python lab/posterior_hedge.py trace --policy posterior:1200:1e9 --scenarios f1,f2,f4
--seeds 5000,5001 --out T.npz``: runs the supervisor (``lab/posterior_supervisor.py``'s
``posterior:N:M:B:K=V`` syntax; margin 1e9: it never moves, so the plant stays at the healthy
set points and the posterior is the one any rule sees until its first move) and keeps, per
episode, the reward, the posterior of each sample after the arming and the candidate held.
``replay T.npz '{"confidence": 0.99}'``: the supervisor's decision rule on the trace's
posterior up to its first move (per episode, when and where to). ``limit T.npz``: per episode, when P(f1) first reaches each level after the onset, and the
highest P(f1) on the non-f1 episodes; then, for rules "move to f1's set points once P(f1) ≥ c
for d samples in a row", the f1 episodes' delay against the kept rule's entry (P(f1) ≥ 5.2 %,
where f1's set points gain the 20 USD/h margin) and the non-f1 episodes it moves on.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from posterior_supervisor import posterior_policy  # this folder (run as a script)

from evaluation.control.posterior_policy import RETURN_TABLE
from evaluation.control.returns import run_episode

#: the samples of one hour (10-s samples)
PER_HOUR = 360.0
#: f1's set points against the healthy ones on the f1 plant, USD/h (the return table)
F1_GAIN_USD_PER_H = RETURN_TABLE["f1"]["f1"] - RETURN_TABLE["f1"]["healthy"]


def trace(policy: str, scenarios: list[str], seeds: list[int], out: str) -> None:
    arrays: dict[str, np.ndarray] = {}
    t0 = time.process_time()
    sup = posterior_policy(policy)
    arrays["hypotheses"] = np.array(sup.diagnoser.hypotheses_)
    arrays["candidates"] = np.array(list(sup.candidates))
    update = sup.diagnoser.update
    act = sup.act
    posts: list[np.ndarray] = []
    targets: list[int] = []

    def recording_update(y: np.ndarray):
        d = update(y)
        posts.append(np.asarray(d.posterior, dtype=np.float64))
        return d

    def recording_act(obs: np.ndarray, info):
        n = len(posts)
        a = act(obs, info)
        if len(posts) == n:
            posts.append(np.full(len(sup.diagnoser.hypotheses_), np.nan))
        targets.append(sup._current)
        return a

    sup.diagnoser.update = recording_update
    sup.act = recording_act
    for sc in scenarios:
        for seed in seeds:
            posts.clear()
            targets.clear()
            tr: dict = {}
            score = run_episode(sup, sc, seed, 3999, trace=tr)
            key = f"{sc}/{seed}"
            arrays[f"{key}/reward"] = np.array(tr["reward"], dtype=np.float64)
            arrays[f"{key}/post"] = np.array(posts)
            arrays[f"{key}/target"] = np.array(targets)
            arrays[f"{key}/onset"] = np.array(tr["onset"][0] or 0)
            print(f"{key}: {score.return_usd:,.1f} USD, {time.process_time() - t0:.0f} s CPU")
    np.savez_compressed(out, **arrays)


def _first(mask: np.ndarray, run: int) -> int | None:
    """The first index at which ``mask`` has held ``run`` samples in a row (its last one)."""
    count = 0
    for i, m in enumerate(mask):
        count = count + 1 if m else 0
        if count >= run:
            return i
    return None


def limit(path: str) -> None:
    z = np.load(path)
    hyps = list(z["hypotheses"])
    f1 = hyps.index("f1")
    episodes = sorted({k.rsplit("/", 1)[0] for k in z.files if k.count("/") == 2})
    p1 = {}
    for ep in episodes:
        post = z[f"{ep}/post"]
        onset = int(z[f"{ep}/onset"])
        p1[ep] = np.nan_to_num(post[onset:, f1] / post[onset:].sum(axis=1))
    levels = (0.01, 0.052, 0.2, 0.5, 0.9, 0.99)
    print(
        "| episode | max P(f1) after onset | samples ≥ 5.2 % | first ≥ "
        + " / ".join(map(str, levels))
        + " |"
    )
    for ep in episodes:
        firsts = [_first(p1[ep] >= c, 1) for c in levels]
        print(
            f"| {ep} | {p1[ep].max():.4f} | {int((p1[ep] >= 0.052).sum())} | "
            + " / ".join("-" if f is None else str(f) for f in firsts)
            + " |"
        )
    f1_eps = [e for e in episodes if e.startswith("f1/")]
    others = [e for e in episodes if not e.startswith("f1/")]
    print(
        "\n| c | d | non-f1 episodes moved | f1 delay, samples (mean, max) | f1 cost USD/episode |"
    )
    for c in (0.052, 0.1, 0.2, 0.3, 0.5, 0.7, 0.9, 0.99):
        for d in (1, 10, 30, 60, 100, 200):
            moved = [e for e in others if _first(p1[e] >= c, d) is not None]
            delays = []
            for e in f1_eps:
                base = _first(p1[e] >= 0.052, 1)
                t = _first(p1[e] >= c, d)
                delays.append(np.inf if t is None else t - (base or 0))
            dl = np.array(delays, dtype=float)
            print(
                f"| {c} | {d} | {len(moved)} of {len(others)} | {dl.mean():.0f}, {dl.max():.0f} | "
                f"{dl.mean() * F1_GAIN_USD_PER_H / PER_HOUR:.0f} |"
            )


def replay(path: str, settings: dict, trust_after: int = 1200) -> None:
    """The supervisor's decision (``settings``: ``PosteriorSupervisor`` keywords) on a trace's
    posterior, up to its first move (after it the trace, taken at the healthy set points, no
    longer is what the supervisor would see): per episode, the first move after the onset."""
    from types import SimpleNamespace

    from evaluation.control.policies import ARM_AFTER
    from evaluation.control.posterior_policy import PosteriorSupervisor

    z = np.load(path)
    hyps = list(z["hypotheses"])
    names = list(z["candidates"])
    table = dict(RETURN_TABLE)
    stub = SimpleNamespace(hypotheses_=hyps)
    episodes = sorted({k.rsplit("/", 1)[0] for k in z.files if k.count("/") == 2})
    print(settings)
    for ep in episodes:
        sup = PosteriorSupervisor(
            "replay", stub, table, {c: np.zeros(2) for c in names}, **settings
        )
        sup._current, sup._faulty_for = names.index("healthy"), 0
        post, onset = z[f"{ep}/post"], int(z[f"{ep}/onset"])
        moves = []
        for t in range(ARM_AFTER, len(post)):
            p = np.eye(len(hyps))[0] if t < ARM_AFTER + trust_after else post[t]
            before = sup._current
            sup._current = sup._decide(p)
            if sup._current != before:
                moves.append(f"{t - onset:+d} {names[sup._current]}")
                break
        print(f"{ep}: {moves[0] if moves else 'no move'}")


if __name__ == "__main__":
    argv = sys.argv[1:]
    if argv[0] == "trace":
        trace(
            argv[argv.index("--policy") + 1],
            argv[argv.index("--scenarios") + 1].split(","),
            [int(s) for s in argv[argv.index("--seeds") + 1].split(",")],
            argv[argv.index("--out") + 1],
        )
    elif argv[0] == "limit":
        limit(argv[1])
    elif argv[0] == "replay":
        import json

        replay(argv[1], json.loads(argv[2]))
