"""Offline comparison of alarm stages on cached residuals (validation seeds only)."""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np

sys.path.insert(0, ".")
from diagnosers.stages.alarm import (
    CUSUM,
    EWMA,
    DirectionalGLR,
    DirectionalProjection,
    HotellingT2,
    calibrate_limit,
    normal_tail_limit,
)
from evaluation.metrics import episode_scores
from evaluation.metrics.intervals import bootstrap_ci
from lab.det_lab import FAULTS, TRACK_NAMES, _episode_cache, folds, residual_cache

W = 100  # warm-up


@dataclass
class Variant:
    name: str
    kind: str = "t2"  # t2 | dir | glr | cusum
    lam: float = 0.3
    target: float = 0.002
    omnibus: float = 0.5  # share of the target given to the T² (dir/glr/cusum)
    window: int = 200
    drift: float = 0.5
    dir_window: int = 300
    limit: str = "tail"  # tail | empirical
    tail_q: float = 0.99


def resid(R: dict, key: str, use_mem: np.ndarray) -> np.ndarray:
    return R[f"r:{key}"] - R[f"e:{key}"] * use_mem


def calib_set(mode: str):
    """[(fold model residual dict, [train episode idx])] per calibration source."""
    if mode == "holdout":
        return [(residual_cache("2"), list(folds(9)[2]))]
    return [(residual_cache(str(k)), list(folds(9)[k])) for k in range(3)]


class Stage:
    def __init__(self, v: Variant, cal: list[np.ndarray], sig: dict[str, np.ndarray]):
        self.v = v
        z = np.concatenate([EWMA(v.lam).filter(e)[W:] for e in cal])
        self.t2 = HotellingT2(centered=False).fit(z)
        k = z.shape[1]
        if v.kind == "t2":
            self.h = calibrate_limit(
                self.t2.score(z)[:, None],
                v.target,
                method="chi2-tail",
                dof=k,
                tail_quantile=v.tail_q,
            )[0]
            if v.limit == "empirical":
                self.h = np.quantile(self.t2.score(z), 1 - v.target)
            return
        t_omni = v.target * v.omnibus
        t_dir = v.target * (1 - v.omnibus)
        dirs = np.array([sig[f] for f in FAULTS])
        self.h2 = (
            calibrate_limit(
                self.t2.score(z)[:, None], t_omni, method="chi2-tail", dof=k, tail_quantile=v.tail_q
            )[0]
            if v.omnibus > 0
            else np.inf
        )
        if v.kind == "dir":
            self.proj = DirectionalProjection().fit(dirs, np.cov(z.T))
            p = self.proj.score(z)
            self.hd = normal_tail_limit(p, t_dir / len(dirs), tail_quantile=v.tail_q)
        else:
            ecal = np.concatenate([e[W:] for e in cal])
            self.proj = DirectionalProjection().fit(dirs, np.cov(ecal.T))
            st = np.concatenate([self._seq(self.proj.score(e))[W:] for e in cal])
            m = st.max(axis=1)
            self.hd = np.quantile(m, 1 - t_dir) * np.ones(len(dirs))

    def _seq(self, p):
        if self.v.kind == "glr":
            return DirectionalGLR(self.v.window).filter(p)
        return CUSUM(self.v.drift).filter(p)

    def alarms(self, e: np.ndarray) -> np.ndarray:
        e = e.copy()
        e[:W] = 0
        z = EWMA(self.v.lam).filter(e)
        t2 = self.t2.score(z)
        if self.v.kind == "t2":
            a = t2 > self.h
        else:
            p = self.proj.score(z) if self.v.kind == "dir" else self._seq(self.proj.score(e))
            a = (t2 > self.h2) | np.any(p > self.hd, axis=1)
        a[:W] = False
        return a


def run(v: Variant, calmode: str = "holdout", model: str = "2", quiet=False) -> dict:
    eps = _episode_cache()
    R = residual_cache(model)
    cal_src = calib_set(calmode)
    # use_mem and v from calibration residuals
    on = np.concatenate(
        [(r[f"r:train/{i}"] - r[f"e:train/{i}"])[W:] for r, idx in cal_src for i in idx]
    )
    off = np.concatenate([r[f"r:train/{i}"][W:] for r, idx in cal_src for i in idx])
    use_mem = (np.sqrt((on**2).mean(0)) < np.sqrt((off**2).mean(0))).astype(float)
    cal = [resid(r, f"train/{i}", use_mem) for r, idx in cal_src for i in idx]
    vres = np.sqrt(np.mean(np.concatenate([c[W:] for c in cal]) ** 2, axis=0))
    cal = [c / vres for c in cal]
    # fault signatures from training faults: faulty minus healthy twin (training seeds 1000-1004
    # are training episodes 0-4 of the model's training set: their healthy twins)
    sig = {}
    for f in FAULTS:
        ds = []
        for i, seed in enumerate(range(1000, 1005)):
            key = f"trainfault/{f}/{seed}"
            on_ = int(eps[f"onset:{key}"])
            rf = resid(R, key, use_mem)
            if len(rf) < on_ + v.dir_window:
                continue  # ended (afterburn) before the window closed
            d = (rf - resid(R, f"train/{i}", use_mem)[: len(rf)]) / vres
            ds.append(d[on_ : on_ + v.dir_window].mean(0))
        s = np.mean(ds, axis=0)
        sig[f] = s / np.linalg.norm(s)
    st = Stage(v, cal, sig)
    out = {"sig": sig, "use_mem": use_mem, "v": vres}
    rfd = []
    for s in range(5000, 5100):
        a = st.alarms(resid(R, f"nominal/{s}", use_mem) / vres)
        rfd.append(episode_scores(a, None)["r_fd"])
    rfd = np.array(rfd)
    ci = bootstrap_ci(rfd)
    out["rfd"] = (rfd.mean(), ci.low, ci.high, (rfd > 0).mean(), rfd.max())
    orf = np.array([eps[f"oracle:paper:nominal/{s}"][0] for s in range(5000, 5100)])
    out["oracle_rfd"] = orf.mean()
    rows = {}
    for tn in TRACK_NAMES:
        for f in FAULTS:
            td, tt, ot, otd, miss = [], [], [], [], 0
            for s in range(5000, 5020):
                key = f"{tn}/{f}/{s}"
                if f"y:{key}" not in eps:
                    continue
                y = eps[f"y:{key}"]
                on_ = int(eps[f"onset:{key}"])
                if on_ < 0 or on_ >= len(y):
                    continue
                a = st.alarms(resid(R, key, use_mem) / vres)
                sc = episode_scores(a, on_)
                o = eps[f"oracle:{tn}:{key}"]
                td.append(sc["r_td"])
                otd.append(o[1])
                if np.isnan(sc["t_dt"]):
                    miss += 1
                elif not np.isnan(o[2]):
                    tt.append(sc["t_dt"])
                    ot.append(o[2])
            tt, ot = np.array(tt), np.array(ot)
            rows[(tn, f)] = (
                np.mean(td),
                np.mean(otd),
                tt.mean(),
                ot.mean(),
                np.mean((tt + 1) / (ot + 1)),
                miss,
            )
    out["rows"] = rows
    if not quiet:
        report(v, calmode, model, out)
    return out


def report(v, calmode, model, out):
    r = out["rfd"]
    print(f"== {v} cal={calmode} model={model} use_mem={out['use_mem']}")
    print(
        f"   r_fd {r[0]:.4f} [{r[1]:.4f}, {r[2]:.4f}] any-alarm {r[3]:.2f} worst {r[4]:.3f} (oracle {out['oracle_rfd']:.4f})"
    )
    for tn in TRACK_NAMES:
        cells = []
        for f in FAULTS:
            td, otd, tt, ot, ratio, miss = out["rows"][(tn, f)]
            cells.append(
                f"{f} {td:.3f}/{otd:.3f} t{tt:.0f}/{ot:.0f} x{ratio:.2f}"
                + (f" m{miss}" if miss else "")
            )
        print(f"   {tn:9s} " + " | ".join(cells))


def table_row(label: str, out: dict) -> str:
    r = out["rfd"]
    cells = [label, f"{r[0]:.4f} [{r[1]:.4f}, {r[2]:.4f}]", f"{r[3]:.2f}", f"{r[4]:.3f}"]
    for tn in TRACK_NAMES:
        for f in FAULTS:
            td, _, tt, _, ratio, miss = out["rows"][(tn, f)]
            cells.append(f"{td:.2f}/{tt:.0f}/×{ratio:.1f}" + (f" m{miss}" if miss else ""))
    return "| " + " | ".join(cells) + " |"


def oracle_row(out: dict) -> str:
    cells = ["oracle (physical limit)", f"{out['oracle_rfd']:.4f}", "", ""]
    for tn in TRACK_NAMES:
        for f in FAULTS:
            _, otd, _, ot, _, _ = out["rows"][(tn, f)]
            cells.append(f"{otd:.2f}/{ot:.0f}")
    return "| " + " | ".join(cells) + " |"


def header() -> str:
    cols = ["variant", "r_fd [95 % CI] (100 healthy)", "any", "worst"]
    cols += [f"{tn[:3]} {f}" for tn in TRACK_NAMES for f in FAULTS]
    return "| " + " | ".join(cols) + " |\n|" + "---|" * len(cols)


def main(argv: list[str]) -> None:
    import json

    specs = json.loads(argv[0])  # [[label, calmode, model, {variant kwargs}], ...]
    lines = []
    first = None
    for label, calmode, model, kw in specs:
        out = run(Variant(name=label, **kw), calmode, model, quiet=True)
        first = first or out
        lines.append(table_row(label, out))
        print(lines[-1], flush=True)
    with open("results/det/table.md", "a") as fh:
        fh.write(header() + "\n" + oracle_row(first) + "\n" + "\n".join(lines) + "\n\n")


if __name__ == "__main__":
    main(sys.argv[1:])


def streaks(v: Variant, calmode: str, model: str, min_len: int = 10) -> None:
    """Where the healthy alarm streaks sit: afterburn gap, inputs against the training range."""
    import fcc_env

    ch = list(fcc_env.MEASUREMENT_NAMES)
    eps = _episode_cache()
    R = residual_cache(model)
    out = run(v, calmode, model, quiet=True)
    use_mem, vres = out["use_mem"], out["v"]
    cal_src = calib_set(calmode)
    cal = [resid(r, f"train/{i}", use_mem) / vres for r, idx in cal_src for i in idx]
    st = Stage(v, cal, out["sig"])
    from evaluation.tracks.track_data import TrackData
    from lab.det_lab import N_TRAIN, val_track

    tr = [
        e.y for e in TrackData(track=val_track("paper").replace(n_train=N_TRAIN)).train_episodes()
    ]
    lo = np.min([t.min(0) for t in tr], axis=0)
    hi = np.max([t.max(0) for t in tr], axis=0)
    gap_all, gap_alarm, n_streak = [], [], 0
    for s in range(5000, 5100):
        y = eps[f"y:nominal/{s}"]
        e = resid(R, f"nominal/{s}", use_mem) / vres
        a = st.alarms(e)
        gap = y[:, ch.index("T_d1")] - y[:, ch.index("T_rg1")]
        gap_all.append(gap[W:])
        gap_alarm.append(gap[a])
        d = np.diff(np.r_[0, a.astype(int), 0])
        starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
        for a0, a1 in zip(starts, ends, strict=True):
            if a1 - a0 >= min_len:
                n_streak += 1
                seg = y[a0:a1]
                outside = [
                    ch[i] for i in range(8) if seg[:, i].min() < lo[i] or seg[:, i].max() > hi[i]
                ]
                print(
                    f"seed {s} samples {a0}-{a1} ({a1 - a0}) gap {gap[a0:a1].mean():.1f} "
                    f"mean e {np.round(e[a0:a1].mean(0), 2)} outside-train-range {outside}"
                )
    ga, gl = np.concatenate(gap_all), np.concatenate(gap_alarm)
    print(
        f"{n_streak} streaks; afterburn gap > 40 °C: {np.mean(ga > 40):.3f} of healthy samples, "
        f"{np.mean(gl > 40) if len(gl) else float('nan'):.3f} of alarmed samples"
    )
