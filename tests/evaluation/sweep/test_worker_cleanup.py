"""A killed sweep driver leaves no worker process behind (``fcc_common.workers.init_worker``, set up by the local backend)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads /proc (Linux)")

ROOT = Path(__file__).resolve().parents[3]  # the repository

DRIVER = textwrap.dedent(
    """
    import sys
    from evaluation.sweep import SimulatedData, SweepConfig, default_specs, run_sweep

    config = SweepConfig(
        diagnosers=default_specs(("limits",)),
        data=SimulatedData(
            scenarios=("nominal",), test_seeds=tuple(range(400)), train_seeds=(900,),
            n_samples=2000,
        ),
    )
    run_sweep(config, sys.argv[1], n_workers=2, progress=False)
    """
)


def _children(pid: int) -> set[int]:
    out = set()
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.add(int(d.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_workers_exit_when_the_driver_is_killed(tmp_path) -> None:
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
    }
    driver = subprocess.Popen(
        [sys.executable, "-c", DRIVER, str(tmp_path / "store")], cwd=ROOT, env=env
    )
    try:
        deadline = time.monotonic() + 60
        kids: set[int] = set()
        while time.monotonic() < deadline and driver.poll() is None:
            kids = _children(driver.pid)
            # two workers and the resource tracker, and the workers have started scoring
            if len(kids) >= 3 and (tmp_path / "store" / "models").is_dir():
                break
            time.sleep(0.2)
        assert driver.poll() is None, "the sweep ended before it could be killed"
        assert len(kids) >= 3, f"workers did not start: children {kids}"
        time.sleep(1.0)
        kids = _children(driver.pid) | kids
        driver.send_signal(signal.SIGKILL)
        driver.wait()
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and any(_alive(p) for p in kids):
            time.sleep(0.1)
        survivors = [p for p in kids if _alive(p)]
        assert not survivors, f"processes {survivors} of the killed driver {driver.pid} survive"
    finally:
        if driver.poll() is None:
            driver.kill()
            driver.wait()
