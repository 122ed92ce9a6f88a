"""Every command turns a failure into one line naming the value, never a traceback (issue 32).

The campaign: each case runs a command's ``main`` in this process and is classed as *clear* (the
expected exit code and a message naming the value), *unclear* (refused, but the message misses
the value), *traceback* (an exception escaped), *accepted* (exit 0 where a refusal was due) or,
outside pytest, *crash* (killed: out of memory or time). Each root cause has several cases:

1. an unusable ``--out`` and ``--import`` failures, refused through
   :func:`fcc_common.invocation.run_command` and :func:`diagnosers.registry.import_modules`;
2. counts beyond the memory budget, refused before any range of seeds is built;
3. advice: "re-run to resume" only after an interruption, no overlap of seed ranges, no
   empty ``--out``; two runs on one store accept each other's identical cells.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import pytest

from diagnosers import registry
from evaluation.discover.cli import main as discover_main
from evaluation.leaderboard.command import main as leaderboard_main
from evaluation.sweep.store import ResultStore, StoreError
from fcc_env.generate import main as generate_main

MAINS: dict[str, Callable[[list[str]], int]] = {
    "generate": generate_main,
    "leaderboard": leaderboard_main,
    "discover": discover_main,
}
#: The modules the campaign runs with ``python -m`` outside pytest.
MODULES = {
    "generate": "fcc_env.generate",
    "leaderboard": "evaluation.leaderboard",
    "discover": "evaluation.discover",
}

#: User modules written into the case folder: each fails to be imported in its own way.
USER_MODULES = {
    "raising_mod": "raise RuntimeError('this module refuses to be imported')\n",
    "syntax_mod": "def broken(:\n    pass\n",
    "notdiag_mod": textwrap.dedent(
        """
        import diagnosers

        @diagnosers.register("not-a-diagnoser")
        class NotADiagnoser:
            pass
        """
    ),
    "failfit_mod": textwrap.dedent(
        """
        import diagnosers
        from diagnosers.registry import diagnoser_class

        @diagnosers.register("fail-fit")
        class FailFit(diagnoser_class("limits")):
            def fit(self, episodes, y=None):
                raise ValueError("fail-fit always fails to train")
        """
    ),
    "clash_plugin": textwrap.dedent(
        """
        from diagnosers.registry import diagnoser_class

        class Clash(diagnoser_class("limits")):
            pass

        class Later(diagnoser_class("limits")):
            pass
        """
    ),
}
#: A distribution whose first entry point has a built-in diagnoser's name.
ENTRY_POINTS = (
    "[fcc_fault_diagnosis.diagnosers]\n"
    "limits = clash_plugin:Clash\n"
    "later-plugin = clash_plugin:Later\n"
)

_LB = ["--quick", "--no-figures", "--no-progress", "--workers", "0"]
#: One short episode to train on and one to score, in this process.
_RUN = [*_LB[1:], "--scenarios", "nominal", "--seeds", "1", "--train-episodes", "1"]
_RUN += ["--n-samples", "300", "--diagnosers", "limits"]

#: ``(id, command, argv, exit code, texts the message must hold, texts it must not)``;
#: ``{tmp}`` is the case folder, ``{file}`` a regular file in it, ``{data}`` a small dataset.
CASES: list[tuple[str, str, list[str], int, tuple[str, ...], tuple[str, ...]]] = [
    # 1. unusable --out
    ("gen-out-etc-passwd", "generate", ["--out", "/etc/passwd/x.csv"], 2, ("/etc/passwd",), ()),
    ("gen-out-under-file", "generate", ["--out", "{file}/x.csv"], 2, ("{file}",), ()),
    ("gen-out-proc", "generate", ["--out", "/proc/fcc-none/x.csv"], 2, ("/proc/fcc-none",), ()),
    ("lb-out-under-file", "leaderboard", [*_LB, "--out", "{file}/lb"], 2, ("{file}",), ()),
    ("lb-out-etc-passwd", "leaderboard", [*_LB, "--out", "/etc/passwd/lb"], 2, ("/etc",), ()),
    ("lb-out-proc", "leaderboard", [*_RUN, "--out", "/proc/fcc-none"], 2, ("/proc",), ()),
    ("disc-out-under-file", "discover", ["--data", "{data}", "--out", "{file}/d"], 2, ("{file}",), ()),
    ("disc-out-proc", "discover", ["--data", "{data}", "--out", "/proc/fcc-none/d"], 2, ("/proc",), ()),
    # 1. --import and plug-ins
    ("import-raises", "leaderboard", [*_LB, "--import", "raising_mod"], 2, ("raising_mod", "refuses"), ()),
    ("import-syntax", "leaderboard", [*_LB, "--import", "syntax_mod"], 2, ("syntax_mod", "line 1"), ()),
    ("import-relative", "leaderboard", [*_LB, "--import", ".foo"], 2, ("'.foo'", "absolute"), ()),
    ("import-not-diagnoser", "leaderboard", [*_LB, "--import", "notdiag_mod"], 2, ("notdiag_mod", "not a diagnoser"), ()),
    ("plugin-clash", "leaderboard", [*_LB, "--diagnosers", "nosuch"], 2, ("'nosuch'", "later-plugin", "Clash"), ()),
    # 2. counts against the memory budget, before any range is built
    ("lb-seeds-1e9", "leaderboard", [*_LB[1:], "--validation", "--seeds", "1000000000", "--diagnosers", "limits"], 2, ("--seeds 1000000000", "GiB"), ()),
    ("lb-train-1e9", "leaderboard", [*_LB, "--train-episodes", "1000000000"], 2, ("--train-episodes 1000000000",), ()),
    ("lb-samples-1e7", "leaderboard", [*_LB, "--n-samples", "10000000"], 2, ("--n-samples 10000000", "GiB"), ()),
    ("track-train-1e9", "leaderboard", ["--track", "paper", *_LB, "--train-episodes", "1000000000"], 2, ("--train-episodes 1000000000",), ()),
    ("gen-seeds-1e9", "generate", ["--out", "{tmp}/g.csv", "--seeds", "0-1000000000"], 2, ("0-1000000000", "GiB"), ()),
    ("gen-samples-1e8", "generate", ["--out", "{tmp}/g.csv", "--samples", "100000000"], 2, ("100000000", "GiB"), ()),
    # 3. advice
    ("lb-train-into-validation", "leaderboard", [*_LB, "--train-episodes", "4500"], 2, ("--train-episodes 4500", "5000"), ()),
    ("lb-seeds-into-training", "leaderboard", [*_LB, "--seeds", "1500"], 2, ("--seeds 1500", "1000"), ()),
    ("gen-out-empty", "generate", ["--out", ""], 2, ("empty",), ()),
    ("lb-out-empty", "leaderboard", [*_LB, "--out", ""], 2, ("empty",), ()),
    ("disc-out-empty", "discover", ["--data", "{data}", "--out", ""], 2, ("empty",), ()),
    ("lb-fit-fails", "leaderboard", [*_RUN, "--import", "failfit_mod", "--diagnosers", "fail-fit", "--out", "{tmp}/ff"], 1, ("fail-fit always fails", "fails the same way"), ("re-run to resume",)),
]  # fmt: skip


def prepare(tmp: Path) -> dict[str, str]:
    """Write the case folder (user modules, a regular file, a plug-in's dist-info)."""
    for name, text in USER_MODULES.items():
        (tmp / f"{name}.py").write_text(text)
    (tmp / "a_file").write_text("not a directory\n")
    info = tmp / "clash_plugin-0.1.dist-info"
    info.mkdir(exist_ok=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: clash-plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(ENTRY_POINTS)
    return {"tmp": str(tmp), "file": str(tmp / "a_file")}


def fill(items: tuple[str, ...] | list[str], names: dict[str, str]) -> list[str]:
    return [t.format(**names) for t in items]


def classify(code: int | None, err: str, expect: int, has: list[str], hasnt: list[str]) -> str:
    """The campaign's class of one outcome (see the module docstring)."""
    if "Traceback (most recent call last)" in err:
        return "traceback"
    if code == 0:
        return "accepted"
    lines = err.strip().splitlines()
    errors = [i for i, ln in enumerate(lines) if ": error: " in ln]  # after argparse's usage
    lines = lines[errors[0] :] if errors else lines
    ok = code == expect and all(h in err for h in has) and not any(h in err for h in hasnt)
    # one line of message (a warning line of a plug-in may precede it)
    return "clear" if ok and 1 <= len(lines) <= 3 else "unclear"


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> str:
    """A two-episode dataset for ``--data`` (generated once)."""
    path = tmp_path_factory.mktemp("data") / "d.csv"
    assert generate_main(["--out", str(path), "--seeds", "0-1", "--samples", "300"]) == 0
    return str(path)


@pytest.mark.parametrize(
    ("case", "cmd", "argv", "expect", "has", "hasnt"), CASES, ids=[c[0] for c in CASES]
)
def test_campaign_case(case, cmd, argv, expect, has, hasnt, tmp_path, monkeypatch, capsys, dataset) -> None:  # fmt: skip
    names = {**prepare(tmp_path), "data": dataset}
    monkeypatch.chdir(tmp_path)  # --import finds the case's modules, as from the command line
    monkeypatch.syspath_prepend(str(tmp_path))  # the plug-in's dist-info
    monkeypatch.setattr(registry, "_ENTRY_POINTS_LOADED", False)
    for name in USER_MODULES:
        monkeypatch.delitem(sys.modules, name, raising=False)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            code: int | None = MAINS[cmd](fill(argv, names))
    except SystemExit as e:
        code = e.code if isinstance(e.code, int) else 1
    finally:
        for name in ("not-a-diagnoser", "fail-fit", "later-plugin"):
            registry.unregister(name)
        registry._ENTRY_POINTS_LOADED = False  # the next test's plug-ins are its own
    err = capsys.readouterr().err + "".join(f"{w.message}\n" for w in caught)
    assert classify(code, err, expect, fill(has, names), list(hasnt)) == "clear", err


def test_plugin_clash_keeps_the_builtin_and_loads_the_rest(tmp_path, monkeypatch) -> None:
    prepare(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    builtin = registry.diagnoser_class("limits")
    try:
        with pytest.warns(RuntimeWarning, match=r"'limits' = 'clash_plugin:Clash'.*kept"):
            registry.load_entry_points(force=True)
        assert registry.diagnoser_class("limits") is builtin
        assert registry.diagnoser_class("later-plugin").__name__ == "Later"
    finally:
        registry.unregister("later-plugin")
        registry._ENTRY_POINTS_LOADED = False


def test_register_refuses_a_class_that_is_not_a_diagnoser() -> None:
    with pytest.raises(ValueError, match=r"register\('x'\) was given <class 'int'>"):
        registry.register("x")(int)  # type: ignore[arg-type]
    assert "x" not in registry.available()


# ---- 3. two runs on one store ------------------------------------------------------------------
RECORD = {"diagnoser": "limits", "scenario": "f1", "seed": 3, "r_fd": 0.01, "t_dt": None}


def test_an_identical_cell_of_another_run_is_kept(tmp_path) -> None:
    st = ResultStore.open(tmp_path, {"k": 1})
    path = st.write_cell("limits", "f1", 3, "h1", {**RECORD, "detect_wall_s": 0.5})
    before = path.read_text()
    # the other run computed the same cell in another time: no error, the file is unchanged
    assert st.write_cell("limits", "f1", 3, "h1", {**RECORD, "detect_wall_s": 0.7}) == path
    assert path.read_text() == before
    with pytest.raises(StoreError, match=r"another run on this store.*one run at a time"):
        st.write_cell("limits", "f1", 3, "h1", {**RECORD, "r_fd": 0.5})


def test_only_an_interruption_advises_a_rerun(capsys) -> None:
    from concurrent.futures.process import BrokenProcessPool

    from evaluation.leaderboard.arguments import build_parser, exit_on_failure

    parser = build_parser()
    died = RuntimeError("scoring failed: BrokenProcessPool: a worker died")
    died.__cause__ = BrokenProcessPool("a worker died")
    for e, code, text in (
        (KeyboardInterrupt(), 130, "re-run the same command to resume"),
        (died, 1, "re-run the same command to resume"),
        (RuntimeError("training failed: x: ValueError: bad"), 1, "fails the same way"),
    ):
        with pytest.raises(SystemExit) as ex:
            exit_on_failure(parser, e)
        assert ex.value.code == code and text in capsys.readouterr().err


# ---- 4. Ray: the local cluster dies with its driver --------------------------------------------
_RAY_DRIVER = """
import time
from evaluation.sweep.backends import RayBackend
backend = RayBackend(1, None)
print("ready", flush=True)
if input() == "close":
    backend.close(cancel=False)
    print("closed", flush=True)
time.sleep(120)
"""


def _ray_driver() -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    proc = subprocess.Popen(
        [sys.executable, "-c", _RAY_DRIVER],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        env=env,
        text=True,
    )
    assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
    return proc


def _alive(procs: dict[int, int], deadline_s: float) -> dict[int, int]:
    """Which of ``procs`` (pid -> start time) are still the same process after ``deadline_s``."""

    def left() -> dict[int, int]:
        out = {}
        for pid, start in procs.items():
            try:
                stat = Path(f"/proc/{pid}/stat").read_bytes().rsplit(b")", 1)[1].split()
            except OSError:
                continue
            if int(stat[19]) == start and stat[0] != b"Z":
                out[pid] = start
        return out

    deadline = time.monotonic() + deadline_s
    while left() and time.monotonic() < deadline:
        time.sleep(0.5)
    return left()


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="the watchdog reads /proc (Linux)")
def test_ray_processes_die_with_a_killed_driver() -> None:
    pytest.importorskip("ray")
    from evaluation.sweep.backends_watchdog import descendants

    proc = _ray_driver()
    try:
        ray_procs = descendants(proc.pid)
        assert len(ray_procs) >= 3  # the watchdog, the GCS server, the raylet and its agents
    finally:
        proc.kill()
        proc.wait()
    assert not _alive(ray_procs, 30), "Ray processes outlived the killed driver"


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="the watchdog reads /proc (Linux)")
def test_a_closed_ray_backend_stops_its_watchdog() -> None:
    pytest.importorskip("ray")
    from evaluation.sweep.backends_watchdog import descendants

    proc = _ray_driver()
    try:
        ray_procs = descendants(proc.pid)
        assert proc.stdin is not None and proc.stdout is not None
        proc.stdin.write("close\n")
        proc.stdin.flush()
        assert proc.stdout.readline().strip() == "closed"
        assert not _alive(ray_procs, 30), "Ray processes outlived ray.shutdown"
        assert proc.poll() is None  # the driver itself was left alone
    finally:
        proc.kill()
        proc.wait()
