"""Score ``catalogue-isolator``'s composition on the member outputs that
``lab/catalogue_members.py`` stored: per column, the share of episodes with both faults named
(95 % Wilson interval), wrong and unknown, and what each member confirmed and when.

The episode's answer is read three ways (each scored by :func:`fcc_env.faults.isolation_outcome`):

* ``final``: the diagnosis at the last sample (what an operator reads at the episode's end);
* ``after 2nd``: the majority label of the alarmed samples from the second fault's onset on
  (the window in which both faults act; unalarmed: missed);
* ``track``: the track's own episode label (:func:`evaluation.metrics.isolation_metrics.
  episode_label`, the majority from the first onset), with its CDR.

    PYTHONPATH=$PWD python lab/catalogue_isolator_lab.py /tmp/catalogue/concurrent --confirm 30
"""

from __future__ import annotations

import argparse
import math
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np

from diagnosers.isolation.composition import Composition
from evaluation.metrics.isolation_metrics import cdr, episode_label
from evaluation.sweep.records import column_labels
from fcc_env.faults import isolation_outcome

MISSED = "missed"


def wilson(k: int, n: int, z: float = 1.96) -> str:
    """``k/n`` with its 95 % Wilson score interval."""
    if n == 0:
        return "–"
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return f"{k}/{n} [{max(centre - half, 0.0):.2f}, {min(centre + half, 1.0):.2f}]"


def outcome(label: str, labels: tuple[str, ...]) -> str:
    if label in (MISSED, ""):
        return MISSED
    return isolation_outcome(label.split("+"), labels) if label != "unknown" else "unknown"


def compose(
    f: dict,
    claims: list[tuple[str, ...]],
    classes: tuple[str, ...],
    confirm: int,
    hold: bool,
    several: list[bool],
    defers: list[tuple[int, ...]],
    confirms: list[int | None],
    name_confirms: list[dict[str, int]] | None = None,
    precedes: list[int | None] | None = None,
) -> tuple[np.ndarray, list[tuple[int, str]]]:
    """The diagnosis per sample and the (sample, name) of each confirmation."""
    comp = Composition(
        claims,
        classes,
        confirm=confirm,
        hold=hold,
        several=several,
        defers=defers or None,
        confirms=confirms,
        name_confirms=name_confirms,
        precedes=precedes,
    )
    alarm, names = f["alarm"], f["diagnosis"]
    T = alarm.shape[1]
    out = np.empty(T, dtype=object)
    seen: list[tuple[int, str]] = []
    for k in range(T):
        out[k] = comp.step([bool(a) for a in alarm[:, k]], [str(n) for n in names[:, k]])[1]
        for name in comp.named():
            if name not in [s for _, s in seen]:
                seen.append((k, name))
    return out.astype(str), seen


def _alone(column: str) -> bool:
    """A part of a pair run alone (``lab/catalogue_members.py --alone``)."""
    return column.startswith("alone:")


def _drop(f: dict, members: set[str]) -> dict:
    """The stored outputs without ``members`` (their rows, and deferrals to them, left out)."""
    names = [str(m) for m in f["member_names"]]
    keep = [i for i, m in enumerate(names) if m not in members]
    if len(keep) == len(names):
        return f
    new = {i: j for j, i in enumerate(keep)}
    defers = [
        "|".join(str(new[int(o)]) for o in str(f["defers"][i]).split("|") if o and int(o) in new)
        for i in keep
    ]
    out = dict(f)
    for key in ("member_names", "claims", "several", "confirms", "alarm", "diagnosis"):
        if key in f:
            out[key] = np.asarray(f[key])[keep]
    out["defers"] = np.array(defers, dtype=str)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("store", type=Path)
    ap.add_argument("--confirm", type=int, default=30)
    ap.add_argument("--no-hold", action="store_true")
    ap.add_argument("--claims", default="", help="member=a|b;member=c: override the claims")
    ap.add_argument("--member-confirm", default="", help="member=N,...: its own confirm")
    ap.add_argument("--defers", default="", help="member=other|other,...: who defers to whom")
    ap.add_argument("--no-defer", action="store_true", help="no member defers to another")
    ap.add_argument("--drop", default="", help="member,...: left out of the composition")
    ap.add_argument(
        "--precedes", default="", help="member=N,...: its run begun N samples first is no echo"
    )
    ap.add_argument(
        "--name-confirm", default="", help="member:name=N,...: the run one of its names needs"
    )
    ap.add_argument("--verbose", action="store_true")
    args = ap.parse_args()
    files = sorted(args.store.glob("*.npz"))
    loaded = [_drop(dict(np.load(p)), set(filter(None, args.drop.split(",")))) for p in files]
    faulty = [f for f in loaded if str(f["column"]) != "nominal" and not _alone(str(f["column"]))]
    classes = tuple(sorted({str(f["column"]) for f in faulty}))
    by_name: dict[str, tuple[str, ...]] = {}
    own = {
        k: int(v) for k, v in (x.split("=") for x in filter(None, args.member_confirm.split(",")))
    }
    first = {k: int(v) for k, v in (x.split("=") for x in filter(None, args.precedes.split(",")))}
    by_member: dict[str, dict[str, int]] = defaultdict(dict)
    for item in filter(None, args.name_confirm.split(",")):
        who, rest = item.split(":")
        name, n = rest.split("=")
        by_member[who][name] = int(n)
    for item in filter(None, args.claims.split(";")):
        k, v = item.split("=")
        by_name[k] = tuple(v.split("|"))
    rows: dict[str, Counter] = defaultdict(Counter)
    binding: list[tuple[float, float, bool]] = []
    cdrs: dict[str, list[float]] = defaultdict(list)
    for f in loaded:
        members = [str(m) for m in f["member_names"]]
        claims = [tuple(str(c).split("|")) for c in f["claims"]]
        claims = [by_name.get(m, c) for m, c in zip(members, claims, strict=True)]
        several = [bool(x) for x in f["several"]]
        if args.defers:
            pairs = dict(x.split("=") for x in args.defers.split(","))
            table = [
                "|".join(str(members.index(o)) for o in pairs.get(m, "").split("|") if o in members)
                for m in members
            ]
            f = {**f, "defers": np.array(table)}
        defers = (
            []
            if args.no_defer
            else [tuple(int(i) for i in str(d).split("|") if i) for d in f["defers"]]
        )
        stored = (
            [int(c) or None for c in f["confirms"]] if "confirms" in f else [None] * len(members)
        )
        confirms = [own.get(m, c) for m, c in zip(members, stored, strict=True)]
        name_confirms = [dict(by_member.get(m, {})) for m in members]
        precedes = [first.get(m) for m in members]
        diag, seen = compose(
            f,
            claims,
            classes,
            args.confirm,
            not args.no_hold,
            several,
            defers,
            confirms,
            name_confirms,
            precedes,
        )
        column = str(f["column"])
        if _alone(column):
            part = column.split(":", 1)[1]
            r = rows[column]
            r["n"] += 1
            r["own"] += any(s == part for _, s in seen)
            wrong = sorted({s for _, s in seen if s != part})
            r["false"] += bool(wrong)
            for s in wrong:
                r[f"false:{s}"] += 1
            if args.verbose:
                print(f"{column} {int(f['seed'])}: confirmed {seen}")
            continue
        if column == "nominal":
            rows[column]["alarmed"] += bool((diag != "").any())
            rows[column]["n"] += 1
            rows[column]["named"] += bool(seen)
            if args.verbose and seen:
                print(f"nominal {int(f['seed'])}: {seen}")
            continue
        labels = tuple(str(x) for x in f["labels"])
        onsets = [int(x) for x in f["onsets"]]
        mapped = column_labels(diag, column)
        last = str(mapped[-1]) or MISSED
        w = mapped[onsets[-1] :]
        alarmed = w[w != ""]
        after = Counter(alarmed.tolist()).most_common(1)[0][0] if alarmed.size else MISSED
        track = episode_label(mapped, onsets[0])
        r = rows[column]
        r["n"] += 1
        for how, lab in (("final", last), ("after", after), ("track", track)):
            r[f"{how}:{outcome(lab, labels)}"] += 1
        c = cdr(mapped, column, onsets[0])
        if not math.isnan(c):
            cdrs[column].append(c)
        for lab, on in zip(labels, onsets, strict=True):
            hit = [k for k, s in seen if s == lab]
            r[f"found:{lab}"] += bool(hit)
            if hit:
                r[f"delay:{lab}"] += hit[0] - on
        if float(f.get("cap_binding", -1.0)) >= 0:
            found_cap = any(s == "blower-capacity" for _, s in seen)
            excess = float(f["cap_excess"]) if "cap_excess" in f else float("nan")
            binding.append((float(f["cap_binding"]), excess, found_cap))
        wrong = [s for _, s in seen if s not in labels]
        r["false names"] += bool(wrong)
        for s in wrong:
            r[f"false:{s}"] += 1
        if args.verbose:
            print(
                f"{column} {int(f['seed'])} onsets {onsets} ch {list(f['channels'])}: "
                f"confirmed {seen} final {last!r} after {after!r} track {track!r}"
            )
    print(f"confirm={args.confirm} hold={not args.no_hold}")
    print(
        "| column | n | both named (final) | (after 2nd onset) | (track label) | track CDR | "
        "unknown (final) | wrong (final) | found per part (mean delay) | false names |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    tot = Counter()
    for column in classes:
        r = rows[column]
        n = r["n"]
        tot.update({k: v for k, v in r.items()})
        found = "; ".join(
            f"{p} {r[f'found:{p}']}/{n}"
            + (f" ({r[f'delay:{p}'] / r[f'found:{p}']:.0f})" if r[f"found:{p}"] else "")
            for p in column.split("+")
        )
        false = ", ".join(f"{k[6:]} {v}" for k, v in r.items() if k.startswith("false:"))
        mean_cdr = f"{np.mean(cdrs[column]):.2f}" if cdrs[column] else "–"
        print(
            f"| {column} | {n} | {wilson(r['final:correct'], n)} | "
            f"{wilson(r['after:correct'], n)} | {wilson(r['track:correct'], n)} | {mean_cdr} | "
            f"{r['final:unknown']} | {r['final:wrong']} | {found} | {false or '–'} |"
        )
    n = tot["n"]
    print(
        f"| all | {n} | {wilson(tot['final:correct'], n)} | {wilson(tot['after:correct'], n)} | "
        f"{wilson(tot['track:correct'], n)} | | {tot['final:unknown']} | {tot['final:wrong']} |"
        " | |"
    )
    if binding:
        shares = ", ".join(f"{b:.2f}/{x:.1f}{'+' if hit else '-'}" for b, x, hit in sorted(binding))
        print(
            "blower cap's binding share after its onset / the command's largest excess over "
            f"it [t/h] (+ named, - not): {shares}"
        )
    alone = sorted(c for c in rows if _alone(c))
    if alone:
        print("| fault alone | n | its name confirmed | another name confirmed (which) |")
        print("|---|---|---|---|")
    for column in alone:
        r = rows[column]
        false = ", ".join(f"{k[6:]} {v}" for k, v in r.items() if k.startswith("false:"))
        print(
            f"| {column[6:]} | {r['n']} | {wilson(r['own'], r['n'])} | "
            f"{wilson(r['false'], r['n'])} ({false or '–'}) |"
        )
    h = rows["nominal"]
    if h["n"]:
        print(
            f"healthy: alarmed {wilson(h['alarmed'], h['n'])}, a name confirmed "
            f"{wilson(h['named'], h['n'])}"
        )


if __name__ == "__main__":
    main()
