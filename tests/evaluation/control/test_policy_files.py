"""Saved PPO policies and the RL commands under bad input (issue 45): a campaign of hostile
policy files and argument sets, each refused in one line naming the file or the value.

Each policy-file case edits a good policy written into ``tmp_path`` (no training: the actor is
built from arrays) and expects :func:`~evaluation.control.rl_policy.load_policy` to raise a
``ValueError`` whose message names the file and matches the case; the command-line cases run
``python -m evaluation.control.rl`` / ``python -m evaluation.control`` in this process and
expect exit code 2, one ``error:`` line naming the value, no traceback, all under an alarm (no
hang). The refusals come before any training or episode, so nothing here needs SB3.
"""

from __future__ import annotations

import contextlib
import functools
import io
import json
import re
import signal
import subprocess
import sys
import zipfile
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from evaluation.control import returns_command, rl
from evaluation.control.rl_policy import ACTIVATIONS, weights_sha256

OBS, HID, ACT = 11, 8, 2


def good_policy() -> rl.MLPPolicy:
    rng = np.random.default_rng(0)
    shapes = {
        "layer0.weight": (HID, OBS),
        "layer0.bias": (HID,),
        "layer1.weight": (ACT, HID),
        "layer1.bias": (ACT,),
    }
    weights = {k: rng.normal(size=s).astype(np.float32) for k, s in shapes.items()}
    config = {
        "format": rl.FORMAT,
        "env_id": "FCC-control-v0",
        "obs_dim": OBS,
        "act_dim": ACT,
        "hidden": [HID],
        "activation": "tanh",
        "obs_mean": [0.0] * OBS,
        "obs_var": [1.0] * OBS,
        "obs_epsilon": 1e-8,
        "obs_clip": 10.0,
        "action_low": [-1.0] * ACT,
        "action_high": [1.0] * ACT,
    }
    return rl.MLPPolicy(config, weights)


@contextlib.contextmanager
def within(seconds: int) -> Iterator[None]:
    """Fail instead of hanging (a FIFO, a bomb inflating)."""

    def hung(*_a: object) -> None:
        raise TimeoutError(f"no answer within {seconds} s")

    old = signal.signal(signal.SIGALRM, hung)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


# ---- hostile policy files ----------------------------------------------------------------------
def _config(d: Path) -> dict:
    return json.loads((d / "policy.json").read_text())


def _set(d: Path, rehash: bool = True, **fields: object) -> None:
    """Edit policy.json's fields (None: remove the field)."""
    config = {k: v for k, v in {**_config(d), **fields}.items() if v is not None}
    (d / "policy.json").write_text(json.dumps(config))


def _npz(d: Path, weights: dict[str, np.ndarray], rehash: bool = True) -> None:
    np.savez(d / "policy.npz", **weights)
    if rehash:
        _set(d, weights_sha256=weights_sha256(weights))


def _weights(d: Path) -> dict[str, np.ndarray]:
    with np.load(d / "policy.npz") as data:
        return {k: data[k] for k in data.files}


@functools.cache
def _bomb() -> bytes:
    """A member that inflates to 4 GiB from a few MiB: written once, by streaming zeros."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
        with zf.open("layer0.weight.npy", "w", force_zip64=True) as fh:
            chunk = bytes(2**24)
            for _ in range(4 * 2**30 // len(chunk)):
                fh.write(chunk)
    return buf.getvalue()


def zip_bomb(d: Path) -> None:
    (d / "policy.npz").write_bytes(_bomb())


def lying_header(d: Path) -> None:
    """An array header declaring 10^12 floats over a member of a few bytes."""
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        buf, {"descr": "<f4", "fortran_order": False, "shape": (10**6, 10**6)}
    )
    with zipfile.ZipFile(d / "policy.npz", "w") as zf:
        zf.writestr("layer0.weight.npy", buf.getvalue() + bytes(16))


def nan_weight(d: Path) -> None:
    w = _weights(d)
    w["layer1.weight"][0, 3] = np.nan
    _npz(d, w)


def other_policys_npz(d: Path) -> None:
    w = _weights(d)
    w["layer0.bias"] = w["layer0.bias"] + 1.0
    _npz(d, w, rehash=False)


def many_arrays(d: Path) -> None:
    _npz(d, {**_weights(d), **{f"x{i:04}": np.zeros(1, np.float32) for i in range(1000)}})


def fifo_json(d: Path) -> None:
    (d / "policy.json").unlink()
    import os

    os.mkfifo(d / "policy.json")


def object_array(d: Path) -> None:
    w: dict[str, np.ndarray] = {**_weights(d), "layer0.bias": np.array([{}] * HID, dtype=object)}
    np.savez(d / "policy.npz", **w)


def truncated(d: Path) -> None:
    data = (d / "policy.npz").read_bytes()
    (d / "policy.npz").write_bytes(data[: len(data) // 2])


def write(name: str, text: str) -> Callable[[Path], None]:
    return lambda d: (d / name).write_text(text)


def edit(**fields: object) -> Callable[[Path], None]:
    return lambda d: _set(d, **fields)


#: (case, how to spoil the good policy, the file named, what the message says)
POLICY_CASES = [
    ("zip-bomb", zip_bomb, "policy.npz", r"declares \d+ bytes uncompressed.*over the cap"),
    ("lying-header", lying_header, "policy.npz", r"shape \(1000000, 1000000\).*corrupted"),
    ("truncated-npz", truncated, "policy.npz", r"not an archive of arrays.*BadZipFile"),
    ("npz-not-zip", write("policy.npz", "hello"), "policy.npz", r"not an archive of arrays"),
    ("object-array", object_array, "policy.npz", r"not an archive of arrays.*allow_pickle"),
    ("nan-weight", nan_weight, "policy.npz", r"\['layer1.weight'\] holds 1 non-finite"),
    ("mixed-files", other_policys_npz, "policy.npz", r"does not match the weights_sha256"),
    ("many-arrays", many_arrays, "policy.npz", r"arrays=\"'x0000', .*\(1000 in all\)\""),
    ("no-hash", edit(weights_sha256=None), "policy.npz", r"does not match the weights_sha256 None"),
    ("json-list", write("policy.json", "[]"), "policy.json", r"policy.json='list'.*JSON object"),
    ("json-broken", write("policy.json", '{"format": '), "policy.json", r"not valid JSON"),
    ("json-nan", write("policy.json", '{"obs_clip": NaN}'), "policy.json", r"not valid JSON.*NaN"),
    (
        "json-binary",
        lambda d: (d / "policy.json").write_bytes(b"\xff\xfe"),
        "policy.json",
        "not valid JSON",
    ),
    ("json-fifo", fifo_json, "policy.json", r"a FIFO"),
    ("no-obs-dim", edit(obs_dim=None), "policy.json", r"misses the fields \['obs_dim'\]"),
    ("obs-dim-str", edit(obs_dim="11"), "policy.json", r"obs_dim='11'.*integer >= 1"),
    ("obs-dim-bool", edit(obs_dim=True), "policy.json", r"obs_dim=True"),
    ("hidden-neg", edit(hidden=[-8]), "policy.json", r"hidden=\[-8\]"),
    ("hidden-other", edit(hidden=[16]), "policy.npz", r"\['layer0.weight'\].shape=\(8, 11\)"),
    ("obs-var-neg", edit(obs_var=[-1.0] * OBS), "policy.json", r"obs_var=.*variances >= 0"),
    ("obs-mean-short", edit(obs_mean=[0.0] * 3), "policy.json", r"obs_mean='length 3'"),
    ("obs-mean-str", edit(obs_mean=["a"] * OBS), "policy.json", r"obs_mean=.*finite numbers"),
    ("clip-zero", edit(obs_clip=0), "policy.json", r"obs_clip=0.*> 0"),
    (
        "action-bounds",
        edit(action_low=[1.0] * ACT, action_high=[-1.0] * ACT),
        "policy.json",
        "low <= high",
    ),
    (
        "activation",
        edit(activation="sigmoid"),
        "policy.json",
        r"activation='sigmoid'.*\['tanh', 'relu'\]",
    ),
    ("activation-list", edit(activation=["tanh"]), "policy.json", r"activation=\['tanh'\]"),
    ("env-id", edit(env_id="FCC-v0"), "policy.json", r"env_id='FCC-v0'.*'FCC-control-v0'"),
    ("format-1", edit(format="fcc-rl-policy/1"), "policy.json", r"format='fcc-rl-policy/1'"),
]


@pytest.mark.parametrize(
    ("case", "spoil", "file", "message"), POLICY_CASES, ids=[c[0] for c in POLICY_CASES]
)
def test_a_hostile_policy_file_is_refused_naming_the_file(case, spoil, file, message, tmp_path):
    rl.save_policy(tmp_path, good_policy())
    spoil(tmp_path)
    with within(60), pytest.raises(ValueError) as e:
        rl.load_policy(tmp_path)
    text = str(e.value)
    assert str(tmp_path / file) in text and re.search(message, text), text
    assert "\n" not in text


def test_a_good_policy_round_trips_and_carries_its_hash(tmp_path):
    policy = good_policy()
    rl.save_policy(tmp_path, policy)
    config = _config(tmp_path)
    assert config["weights_sha256"] == weights_sha256(policy.weights)
    again = rl.load_policy(tmp_path)
    obs = np.random.default_rng(1).normal(size=(5, OBS))
    assert np.array_equal(again.act(obs), policy.act(obs))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["policy.json", "policy.npz"]


def test_the_activation_is_honoured(tmp_path):
    policy = good_policy()
    relu = rl.MLPPolicy({**policy.config, "activation": "relu"}, policy.weights)
    rl.save_policy(tmp_path, relu)
    obs = np.random.default_rng(2).normal(size=(7, OBS))
    w0, b0, w1, b1 = (
        policy.weights[k] for k in ("layer0.weight", "layer0.bias", "layer1.weight", "layer1.bias")
    )
    expected = np.clip(np.maximum(obs.astype(np.float32) @ w0.T + b0, 0) @ w1.T + b1, -1, 1)
    np.testing.assert_allclose(rl.load_policy(tmp_path).act(obs), expected, rtol=1e-5)
    assert set(ACTIVATIONS) == {"tanh", "relu"}


def test_a_policy_for_another_env_loads_when_that_env_is_asked_for(tmp_path):
    rl.save_policy(
        tmp_path, rl.MLPPolicy({**good_policy().config, "env_id": "X-v0"}, good_policy().weights)
    )
    assert rl.load_policy(tmp_path, env_id="X-v0").config["env_id"] == "X-v0"


def test_loading_never_runs_code(tmp_path):
    """An object array (what a pickle payload needs) is refused, and nothing runs."""
    marker = tmp_path / "ran"

    class Payload:
        def __reduce__(self):
            return (Path.touch, (marker,))

    rl.save_policy(tmp_path, good_policy())
    np.savez(
        tmp_path / "policy.npz",
        **{**_weights(tmp_path), "layer0.bias": np.array([Payload()], dtype=object)},
    )
    assert not marker.exists()
    with pytest.raises(ValueError, match="allow_pickle"):
        rl.load_policy(tmp_path)
    assert not marker.exists()


# ---- bad argument sets -------------------------------------------------------------------------
MAINS = {"rl": rl.main, "control": returns_command.main}
_T = ["train", "--out", "{tmp}/rl"]
#: (case, command, argv, what the one error line says)
CLI_CASES = [
    ("batch-1", "rl", [*_T, "--batch-size", "1"], r"--batch-size=1 is outside .*2\.\.32768"),
    (
        "batch-over-buffer",
        "rl",
        [*_T, "--envs", "4", "--n-steps", "8"],
        r"--batch-size=8192 .*2\.\.32 \(--n-steps 8 x --envs 4\)",
    ),
    (
        "buffer-1",
        "rl",
        [*_T, "--n-steps", "1", "--envs", "1", "--batch-size", "2"],
        r"--n-steps x --envs=1 .*>= 2",
    ),
    (
        "hidden-1e8",
        "rl",
        [*_T, "--hidden", "100000000"],
        r"--hidden 100000000 .* GiB.*memory budget of 4 GiB",
    ),
    (
        "hidden-two-wide",
        "rl",
        [*_T, "--hidden", "30000,30000"],
        r"--hidden 30000,30000 .*memory budget",
    ),
    ("hidden-text", "rl", [*_T, "--hidden", "64,x"], r"--hidden='64,x'"),
    ("hidden-zero", "rl", [*_T, "--hidden", "64,0"], r"--hidden=\(64, 0\)"),
    (
        "n-steps-1e9",
        "rl",
        [*_T, "--n-steps", "1000000000", "--envs", "4"],
        r"--n-steps 1000000000 x --envs 4 .*memory budget",
    ),
    ("envs-1e6", "rl", [*_T, "--envs", "1000000"], r"--seed=1000 .*1000\.\.-995000"),
    ("val-seeds-1e4", "rl", [*_T, "--val-seeds", "10000"], r"--val-seeds=10000 .*0\.\.1000"),
    ("val-seeds-neg", "rl", [*_T, "--val-seeds", "-1"], r"--val-seeds=-1"),
    ("minutes-inf", "rl", [*_T, "--minutes", "inf"], r"--minutes=inf .*finite"),
    ("minutes-nan", "rl", [*_T, "--minutes", "nan"], r"--minutes=nan"),
    ("lr-nan", "rl", [*_T, "--lr", "nan"], r"--lr/--gamma=\(nan"),
    ("reward-scale-inf", "rl", [*_T, "--reward-scale", "inf"], r"--reward-scale=inf"),
    (
        "torch-threads-1e6",
        "rl",
        [*_T, "--torch-threads", "1000000"],
        r"--torch-threads=1000000 .*CPU cores",
    ),
    (
        "seed-abbrev",
        "rl",
        ["evaluate", "--policy", "{tmp}", "--see", "3"],
        r"unrecognized arguments: --see 3",
    ),
    (
        "eval-seeds-1e9",
        "rl",
        ["evaluate", "--policy", "{good}", "--seeds", "1e9"],
        r"invalid int value: '1e9'",
    ),
    (
        "eval-seeds-huge",
        "rl",
        ["evaluate", "--policy", "{good}", "--seeds", "1000000000", "--out", "{tmp}/o"],
        r"--seeds 1000000000 .*1\.\.1000 \(test seeds 0\.\.999",
    ),
    (
        "eval-policy-file",
        "rl",
        ["evaluate", "--policy", "{good}/policy.json"],
        r"no policy.json there",
    ),
    (
        "eval-policy-bad",
        "rl",
        ["evaluate", "--policy", "{bad}", "--out", "{tmp}/o"],
        r"policy.json='list'",
    ),
    (
        "control-seeds-1e9",
        "control",
        ["--seeds", "1000000000", "--out", "{tmp}/c"],
        r"--seeds 1000000000 .*1\.\.1000",
    ),
    (
        "control-seeds-1001",
        "control",
        ["--seeds", "1001", "--out", "{tmp}/c"],
        r"--seeds 1001 .*training seeds 1000",
    ),
    ("control-seed-abbrev", "control", ["--seed", "1"], r"unrecognized arguments: --seed 1"),
    ("control-steps-0", "control", ["--steps", "0", "--out", "{tmp}/c"], r"--steps 0"),
]


@pytest.mark.parametrize(
    ("case", "cmd", "argv", "message"), CLI_CASES, ids=[c[0] for c in CLI_CASES]
)
def test_a_bad_argument_set_is_one_line_with_exit_code_2(
    case, cmd, argv, message, tmp_path, capsys
):
    rl.save_policy(tmp_path / "good", good_policy())
    (tmp_path / "bad").mkdir()
    rl.save_policy(tmp_path / "bad", good_policy())
    (tmp_path / "bad" / "policy.json").write_text("[]")
    names = {"tmp": str(tmp_path), "good": str(tmp_path / "good"), "bad": str(tmp_path / "bad")}
    with within(120), pytest.raises(SystemExit) as e:
        MAINS[cmd]([a.format(**names) for a in argv])
    err = capsys.readouterr().err
    assert e.value.code == 2, err
    assert "Traceback" not in err
    errors = [ln for ln in err.splitlines() if ": error: " in ln]
    assert len(errors) == 1 and re.search(message, errors[0]), err
    assert not (tmp_path / "rl").exists()  # refused before any work


def test_the_command_refuses_a_zip_bomb_in_one_line(tmp_path):
    """As a user runs it: a separate process, a time limit, no traceback."""
    rl.save_policy(tmp_path, good_policy())
    zip_bomb(tmp_path)
    root = Path(__file__).resolve().parents[3]
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "evaluation.control.rl",
            "evaluate",
            "--policy",
            str(tmp_path),
            "--out",
            str(tmp_path / "o"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=root,
        env={"PYTHONPATH": str(root)},
    )
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert "policy.npz" in proc.stderr and "over the cap" in proc.stderr
