"""Every command turns a failure into one line naming the value, never a traceback (issue 32).

The campaign: each case runs a command's ``main`` in this process and is classed as *clear* (the
expected exit code and a message naming the value), *unclear* (refused, but the message misses
the value), *traceback* (an exception escaped), *accepted* (exit 0 where a refusal was due) or,
outside pytest, *crash* (killed: out of memory or time). Each root cause has several cases:

1. an unusable ``--out`` and ``--import`` failures, refused through
   :func:`fcc_common.invocation.run_command` and :func:`diagnosers.registry.import_modules`;
2. counts beyond the memory budget, refused before any range of seeds is built;
3. advice: "re-run to resume" only after an interruption, no overlap of seed ranges, no
   empty ``--out``; two runs on one store accept each other's identical cells;
4. (issue 45) no prefix matching of flags (``--seed`` is not ``--seeds``), bounded counts in every
   command (the isolation study and tables, the closed-loop report, the benchmarks), and a
   Ctrl-C anywhere ends in one line with exit code 130, workers included.
"""

from __future__ import annotations

import inspect
import os
import signal
import subprocess
import sys
import textwrap
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import pytest

from bench import detector_speed, simulator_speed, sweep_speed, vector_speed
from diagnosers import registry
from evaluation.discover.cli import main as discover_main
from evaluation.isolation import isolability, study
from evaluation.leaderboard.command import main as leaderboard_main
from evaluation.sweep.store import ResultStore, StoreError
from fcc_common.invocation import command_parser, run_command
from fcc_env import closed_loop_report
from fcc_env.generate import main as generate_main

MAINS: dict[str, Callable[[list[str]], int]] = {
    "generate": generate_main,
    "leaderboard": leaderboard_main,
    "discover": discover_main,
    "study": study.main,
    "isolability": isolability.main,
    "clreport": closed_loop_report.main,
    "simspeed": simulator_speed.main,
    "vecspeed": vector_speed.main,
    "detspeed": detector_speed.main,
    "sweepspeed": sweep_speed.main,
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
    # 4. no prefix matching: a near miss is refused, never read as another flag
    ("abbrev-lb-seed", "leaderboard", [*_LB, "--seed", "1"], 2, ("unrecognized arguments: --seed 1",), ()),
    ("abbrev-lb-train", "leaderboard", [*_LB, "--train", "1"], 2, ("unrecognized arguments: --train",), ()),
    ("abbrev-gen-seed", "generate", ["--out", "{tmp}/g.csv", "--seed", "3"], 2, ("--seed 3",), ()),
    ("abbrev-study-n", "study", ["--n", "3"], 2, ("--n 3",), ()),
    ("abbrev-clr-term", "clreport", ["--out", "{tmp}/c", "--term", "3"], 2, ("--term 3",), ()),
    # 4. bounded counts, refused before any training or simulation
    ("study-seeds-1e9", "study", ["--n-seeds", "1000000000", "--out", "{tmp}/s"], 2, ("n_seeds=1000000000", "GiB"), ()),
    ("study-test-into-training", "study", ["--seeds", "test", "--n-seeds", "2000", "--out", "{tmp}/s"], 2, ("n_seeds=2000", "training seeds 1000"), ()),
    ("study-seeds-0", "study", ["--n-seeds", "0", "--out", "{tmp}/s"], 2, ("n_seeds=0",), ()),
    ("study-unknown-over", "study", ["--n-unknown", "30", "--out", "{tmp}/s"], 2, ("n_unknown=30", "[0, 20]"), ()),
    ("study-isolators-list", "study", ["--isolators", "[]", "--out", "{tmp}/s"], 2, ("isolators=[]",), ()),
    ("study-isolators-json", "study", ["--isolators", "[[", "--out", "{tmp}/s"], 2, ("--isolators '[['", "not valid JSON"), ()),
    ("study-track", "study", ["--track", "paper,nope", "--out", "{tmp}/s"], 2, ("'nope'",), ()),
    ("study-out-under-file", "study", ["--out", "{file}/s"], 2, ("{file}",), ()),
    ("isol-seeds-1e9", "isolability", ["--seeds", "1000000000"], 2, ("n_seeds=1000000000",), ()),
    ("isol-horizon-1e12", "isolability", ["--horizon", "1000000000000"], 2, ("horizon=1000000000000",), ()),
    ("isol-track", "isolability", ["--track", "nope"], 2, ("'nope'",), ()),
    ("clr-terminations-1e9", "clreport", ["--out", "{tmp}/c", "--terminations", "1000000000"], 2, ("--terminations=1000000000", "[0, 10000]"), ()),
    ("clr-terminations-neg", "clreport", ["--out", "{tmp}/c", "--terminations", "-1"], 2, ("--terminations=-1",), ()),
    ("clr-response-1e12", "clreport", ["--out", "{tmp}/c", "--response-samples", "1000000000000"], 2, ("--response-samples 1000000000000", "GiB"), ()),
    ("clr-horizon-1e11", "clreport", ["--out", "{tmp}/c", "--horizon", "100000000000"], 2, ("--horizon 100000000000", "GiB"), ()),
    ("clr-seeds-negative", "clreport", ["--out", "{tmp}/c", "--seeds", "-1"], 2, ("seeds=(-1,)",), ()),
    ("clr-out-empty", "clreport", ["--out", ""], 2, ("empty",), ()),
    ("sim-episodes-1e8", "simspeed", ["--episodes", "100000000"], 2, ("--episodes 100000000", "GiB"), ()),
    ("sim-steps-0", "simspeed", ["--steps", "0"], 2, ("--steps=0",), ()),
    ("vec-envs-1e8", "vecspeed", ["--envs", "100000000"], 2, ("--envs 100000000", "GiB"), ()),
    ("det-bank-1e5", "detspeed", ["--bank", "100000"], 2, ("--bank=100000",), ()),
    ("det-epochs-0", "detspeed", ["--epochs", "0"], 2, ("--epochs=0",), ()),
    ("sweep-seeds-float", "sweepspeed", ["--seeds", "1e9", "--skip-cli"], 2, ("'1e9'",), ()),
    ("sweep-seeds-5000", "sweepspeed", ["--seeds", "1,5000", "--skip-cli"], 2, ("--seeds 5000", "training seeds 1000"), ()),
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


# ---- 4. Ctrl-C: one line, exit code 130, anywhere -------------------------------------------
#: Every ``python -m`` command of the packages and of bench/ (the lab scripts are a record, run
#: at their commit).
COMMAND_MODULES = (
    "evaluation.leaderboard.command",
    "evaluation.discover.cli",
    "evaluation.control.returns_command",
    "evaluation.control.rl_command",
    "evaluation.isolation.study",
    "evaluation.isolation.isolability",
    "fcc_env.generate",
    "fcc_env.demo",
    "fcc_env.closed_loop_report",
    "fcc_env.closed_loop_analysis",
    "bench.control_speed",
    "bench.detector_speed",
    "bench.filter_speed",
    "bench.bank_speed",
    "bench.loop_speed",
    "bench.simulator_speed",
    "bench.sweep_speed",
    "bench.vector_speed",
    "bench.scaling",
)


@pytest.mark.parametrize("module", COMMAND_MODULES)
def test_every_command_runs_through_run_command(module: str) -> None:
    """A command that parses on its own would let a Ctrl-C, or a bad value found late, print a
    traceback: each ``main`` hands its work to :func:`run_command`."""
    import importlib

    main = importlib.import_module(module).main
    assert "run_command(" in inspect.getsource(main), module


def test_an_interruption_is_one_line_with_exit_code_130(capsys) -> None:
    parser = command_parser("demo.cmd", "A demo.", (("", "runs"),))

    def body(_args) -> int:
        raise KeyboardInterrupt

    with pytest.raises(SystemExit) as e:
        run_command(parser, body, [], on_interrupt="re-run it")
    err = capsys.readouterr().err
    assert e.value.code == 130
    assert err.strip().splitlines() == [
        "python -m demo.cmd: interrupted (Ctrl-C); files written so far are whole: re-run it"
    ]


def test_abbreviations_are_off_in_every_parser() -> None:
    parser = command_parser("demo.cmd", "A demo.", (("", "runs"),))
    parser.add_argument("--seeds", type=int)
    assert parser.allow_abbrev is False
    with pytest.raises(SystemExit):
        parser.parse_args(["--seed", "1"])


def _read_until(proc: subprocess.Popen[bytes], text: bytes, timeout_s: float) -> bytes:
    """Stderr of ``proc`` up to ``text`` (tqdm writes ``\\r``, no newline: read bytes)."""
    import selectors

    assert proc.stderr is not None
    seen = b""
    sel = selectors.DefaultSelector()
    sel.register(proc.stderr, selectors.EVENT_READ)
    deadline = time.monotonic() + timeout_s
    while text not in seen and time.monotonic() < deadline and proc.poll() is None:
        if sel.select(timeout=0.5):
            seen += os.read(proc.stderr.fileno(), 4096)
    return seen


def test_ctrl_c_in_a_sweep_with_workers_prints_one_line(tmp_path) -> None:
    """A real SIGINT to the whole process group, as a terminal sends it: the driver reports it
    in one line and resumes on a re-run; the spawn workers, interrupted too, print nothing."""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    cmd = [sys.executable, "-m", "evaluation.leaderboard", "--quick", "--workers", "2"]
    cmd += ["--no-figures", "--out", str(tmp_path / "lb")]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env, start_new_session=True
    )
    try:
        before = _read_until(proc, b"training", 180)
        assert b"training" in before, before.decode(errors="replace")
        os.killpg(proc.pid, signal.SIGINT)
        _, rest = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    err = (before + rest).decode(errors="replace")
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert err.count("interrupted") == 1 and "re-run the same command to resume" in err
