"""The closed-loop report: signature semantics, sign conventions, the CLI's files, stability."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from fcc_env.closed_loop import visibility_threshold
from fcc_env.closed_loop_analysis import stability_cases
from fcc_env.closed_loop_report import (
    SIGNATURE_CHANNELS,
    ReportConfig,
    count_terminations,
    fault_deltas,
    main,
    masking_table,
    signature_rows,
    signatures_table,
    trace_signature,
)

# A tiny configuration: enough samples after onset for the fast parts of a signature to show.
TINY = ReportConfig(horizon=400, onset=100, seeds=(5000,), response_samples=80)


def test_trace_signature_semantics() -> None:
    delta = np.zeros(100)
    delta[30] = 5.0  # before onset: ignored
    delta[45] = 0.5  # below the threshold
    delta[47] = 1.0  # first beyond 0.9: t3σ = 47 − 40
    delta[60] = -2.0  # the largest |Δ| after onset, sign kept
    delta[-10:] = 0.3
    s = trace_signature(delta, onset=40, threshold=0.9, final_window=10)
    assert (s.peak, s.peak_at, s.t3sigma) == (-2.0, 20, 7)
    assert s.final == pytest.approx(0.3)


def test_trace_signature_never_and_at_onset() -> None:
    assert trace_signature(np.full(50, 0.5), onset=10, threshold=0.9).t3sigma is None
    step = np.r_[np.zeros(10), np.ones(40)]
    assert trace_signature(step, onset=10, threshold=0.9).t3sigma == 0  # at onset, not "never"
    with pytest.raises(ValueError, match="onset=60"):
        trace_signature(step, onset=60, threshold=0.9)


def test_visibility_thresholds() -> None:
    assert visibility_threshold("T_rx") == pytest.approx(0.9)
    assert visibility_threshold("T_dg") == pytest.approx(1.5)
    assert visibility_threshold("R_ar") == pytest.approx(3 * 0.005 * 148.4)
    assert visibility_threshold("u_F") == pytest.approx(3 * 0.005 * 416.6667)
    with pytest.raises(ValueError, match="channel='P_rg'"):
        visibility_threshold("P_rg")


def test_config_refuses_an_onset_outside_the_horizon() -> None:
    with pytest.raises(ValueError, match="onset=400"):
        ReportConfig(horizon=400, onset=400)
    assert ReportConfig(horizon=400).onset == 200


@pytest.fixture(scope="module")
def f1_runs():
    return [fault_deltas("f1", loop, TINY) for loop in ("open", "closed")]


def test_f1_sign_conventions(f1_runs) -> None:
    open_, closed = f1_runs
    rows = {(r.loop, r.channel): r.signature for r in signature_rows(f1_runs)}
    # faulty − healthy: a denser catalyst heats the regenerator at fixed air (spec §3)
    assert rows[("open", "T_rg1")].final > 0
    assert rows[("open", "T_rx")].peak > 0 and rows[("open", "T_rx")].peak_at == 0
    # open loop the valve and the air are the program's: no difference at all
    assert not open_.deltas["u_F"].any() and not open_.deltas["R_ar"].any()
    assert not open_.deltas["T_rx"][:, : open_.onset].any()  # nothing before onset
    # closed loop the T_rg1 loop holds its temperature and the valve carries the fault
    assert rows[("closed", "u_F")].final > visibility_threshold("u_F")
    assert abs(rows[("closed", "T_rg1")].final) < abs(rows[("open", "T_rg1")].final)
    assert closed.deltas["T_rx"].shape == (1, TINY.horizon)


def test_tables_have_a_row_per_channel(f1_runs) -> None:
    rows = signature_rows(f1_runs)
    assert len(rows) == 2 * len(SIGNATURE_CHANNELS)
    table = signatures_table(rows).splitlines()
    assert len(table) == 2 + len(SIGNATURE_CHANNELS)
    masking = masking_table(rows).splitlines()
    assert len(masking) == 3 and masking[2].startswith("| f1 |") and "T_rg1" in masking[2]


def test_cli_writes_every_file(tmp_path, capsys) -> None:
    out = tmp_path / "report"
    argv = ["--out", str(out), "--horizon", "300", "--seeds", "5000", "--response-samples", "80"]
    assert main([*argv, "--terminations", "2"]) == 0
    names = {p.name for p in out.iterdir()}
    assert names == {
        "stability.md", "responses.png", "fault_signatures.md", "fault_signatures.csv",
        "closed_minus_open.png", "terminations.json",
    }  # fmt: skip
    for png in ("responses.png", "closed_minus_open.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with open(out / "fault_signatures.csv", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 4 * 2 * len(SIGNATURE_CHANNELS)
    assert {r["loop"] for r in rows} == {"open", "closed"}
    assert "terminations" in capsys.readouterr().out


def test_count_terminations_structure() -> None:
    t = count_terminations(3, horizon=20, chunk=2)
    assert t["episodes"] == 3 and t["seeds"] == [5000, 5002]
    assert t["open_loop"]["terminations"] == 0 and t["closed_loop"]["terminations"] == 0


def test_stability_table_rows_all_stable() -> None:
    cases = stability_cases()
    assert len(cases) == 1 + 4 + 16
    assert all(c.stable for c in cases), [c.name for c in cases if not c.stable]
