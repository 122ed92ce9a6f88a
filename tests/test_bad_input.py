"""Bad input gives one clear message naming the value or the file (issue items 7-11)."""

from __future__ import annotations

import builtins
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import fcc_env
from diagnosers import Diagnoser, Episode, diagnoser_class, make
from evaluation.sweep.store import ResultStore, StoreError
from fcc_env import simulate_episodes

CH = tuple(fcc_env.MEASUREMENT_NAMES)


@pytest.fixture(scope="module")
def episodes() -> list[Episode]:
    b = simulate_episodes([0, 1], 400)
    return [Episode(b.observations[i], CH, b.sample_time_s) for i in range(2)]


@pytest.fixture(scope="module")
def pca(episodes) -> Diagnoser:
    return make("pca").fit(episodes)


# ---- items 8-10: diagnosers ------------------------------------------------------------------
def test_arrays_instead_of_episodes(episodes, pca) -> None:
    y = episodes[0].y
    with pytest.raises(ValueError, match=r"fit takes Episode .*numpy\.ndarray of shape \(400, 8\)"):
        make("pca").fit(y)
    with pytest.raises(ValueError, match=r"fit takes Episode .*Episode\(y, channels"):
        make("pca").fit([y])
    with pytest.raises(ValueError, match=r"detect takes Episode .*numpy\.ndarray"):
        pca.detect(y)


def test_detect_refuses_another_sample_time_or_channels(episodes, pca) -> None:
    ep = episodes[0]
    with pytest.raises(ValueError, match=r"sample_time_s=5\.0 differs .* 10\.0 s"):
        pca.detect(Episode(ep.y, CH, 5.0))
    with pytest.raises(ValueError, match=r"episode channels .* differ"):
        pca.detect(Episode(ep.y[:, ::-1], CH[::-1], ep.sample_time_s))


def test_a_string_as_channel_list_is_refused(episodes) -> None:
    with pytest.raises(ValueError, match=r"channels='T_rx' is outside"):
        Episode(np.zeros((3, 4)), "T_rx", 10.0)
    with pytest.raises(ValueError, match=r"channels='T_rx' is outside"):
        make("limits", channels="T_rx").fit(episodes)


@pytest.mark.parametrize("name", ["limits", "pca", "arx-band", "lrgf-mem"])
def test_constant_training_data_is_refused(name) -> None:
    const = [Episode(np.ones((300, 8)), CH, 10.0)]
    with pytest.raises(ValueError, match=rf"{name} cannot be trained: .* constant .*'T_rx'"):
        make(name, **diagnoser_class(name).fast_params()).fit(const)


@pytest.mark.parametrize(
    ("params", "match"),
    [
        ({"seed": "a"}, r"seed='a' is outside the allowed range"),
        ({"seed": -1}, r"seed=-1 is outside the allowed range"),
        ({"seed": 1.0}, r"seed=1\.0 is outside the allowed range"),
        ({"lr": "fast"}, r"lr='fast' is outside the allowed range"),
        ({"relations": [["T_rx", []]]}, r"relations=.*\('T_rx' has no inputs\)"),
        ({"relations": [["T_rx", ["T_rx", "T_fp"]]]}, r"\('T_rx' is its own input\)"),
        ({"relations": []}, r"relations=\[\] is outside"),
    ],
)
def test_bad_lrgf_mem_settings_are_refused_in_fit(episodes, params, match) -> None:
    with pytest.raises(ValueError, match=match):
        make("lrgf-mem", **{**diagnoser_class("lrgf-mem").fast_params(), **params}).fit(episodes)


def test_pca_non_numeric_hyperparameter(episodes) -> None:
    with pytest.raises(ValueError, match=r"alpha='x' is outside the allowed range"):
        make("pca", alpha="x").fit(episodes)


# ---- items 8-9: saved diagnosers -------------------------------------------------------------
def _edit_config(d: Path, **changes) -> None:
    cfg = json.loads((d / "config.json").read_text())
    for k, v in changes.items():
        if k == "alpha":
            cfg["params"]["alpha"] = v
        else:
            cfg[k] = v
    (d / "config.json").write_text(json.dumps(cfg))


def test_saved_config_is_validated_on_load(pca, tmp_path) -> None:
    d = pca.save(tmp_path / "m")
    _edit_config(d, alpha=5)
    with pytest.raises(ValueError, match=r"config\.json: alpha=5 is outside the allowed range"):
        Diagnoser.load(d)


def test_truncated_state_file(pca, tmp_path) -> None:
    d = pca.save(tmp_path / "m")
    data = (d / "state.npz").read_bytes()
    (d / "state.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match=r"state\.npz is missing, truncated .*BadZipFile"):
        Diagnoser.load(d)


@pytest.fixture(scope="module")
def lrgf_dir(episodes, tmp_path_factory) -> Path:
    params = {**diagnoser_class("lrgf-mem").fast_params(), "max_epochs": 5, "mem_max_epochs": 2}
    diag = make("lrgf-mem", **params).fit(episodes)
    return diag.save(tmp_path_factory.mktemp("lrgf") / "m")


def _copy(src: Path, dst: Path) -> Path:
    dst.mkdir()
    for p in src.iterdir():
        (dst / p.name).write_bytes(p.read_bytes())
    return dst


def test_relabelled_model_is_refused(lrgf_dir, tmp_path) -> None:
    d = _copy(lrgf_dir, tmp_path / "m")
    _edit_config(d, diagnoser="lrgf-mem-paper")
    with pytest.raises(ValueError, match=r"config\.json: .*LRGFMEMPaper, but .*LRGFMEM'"):
        Diagnoser.load(d)
    # without the class field, the state's structure still gives it away
    cfg = json.loads((d / "config.json").read_text())
    del cfg["class"]
    (d / "config.json").write_text(json.dumps(cfg))
    with pytest.raises(ValueError, match=r"state\.npz does not fit a 'lrgf-mem-paper'"):
        Diagnoser.load(d)


@pytest.mark.parametrize("content", [b"garbage, not a model", b"\x80\x02csubprocess\nrun\n."])
def test_garbage_weights_file(lrgf_dir, tmp_path, content) -> None:
    d = _copy(lrgf_dir, tmp_path / "m")
    (d / "weights.pt").write_bytes(content)
    with pytest.raises(ValueError) as e:
        Diagnoser.load(d)
    msg = str(e.value)
    assert "weights.pt is not a valid model file" in msg
    assert "weights_only" not in msg and e.value.__cause__ is None


# ---- issue 45: a save never writes through a link ----------------------------------------------
def test_save_refuses_a_linked_target_directory(pca, tmp_path) -> None:
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    link = tmp_path / "model"
    link.symlink_to(elsewhere, target_is_directory=True)
    with pytest.raises(ValueError, match=rf"{link} is a symbolic link .*refusing to save"):
        pca.save(link)
    assert list(elsewhere.iterdir()) == []
    dangling = tmp_path / "dangling"
    dangling.symlink_to(tmp_path / "nowhere")
    with pytest.raises(ValueError, match=r"dangling is a symbolic link"):
        pca.save(dangling)
    assert not (tmp_path / "nowhere").exists()


def test_save_replaces_a_linked_file_and_leaves_its_target(pca, tmp_path) -> None:
    out = pca.save(tmp_path / "model")
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    for name in ("state.npz", "config.json"):
        (out / name).unlink()
        (out / name).symlink_to(victim)
    pca.save(out)
    assert victim.read_text() == "keep me"
    assert not (out / "state.npz").is_symlink() and not (out / "config.json").is_symlink()
    assert Diagnoser.load(out).get_params() == pca.get_params()


def test_save_of_torch_modules_replaces_linked_files(lrgf_dir, tmp_path) -> None:
    diag = Diagnoser.load(lrgf_dir)
    out = diag.save(tmp_path / "model")
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    for name in ("weights.pt", "models.json"):
        (out / name).unlink()
        (out / name).symlink_to(victim)
    diag.save(out)
    assert victim.read_text() == "keep me"
    assert Diagnoser.load(out).get_params() == diag.get_params()


# ---- item 11: the result store ---------------------------------------------------------------
def test_a_cell_path_that_is_a_directory_is_reported_when_read(tmp_path) -> None:
    st = ResultStore.open(tmp_path / "s", {"d": 1})
    st.cell_path("limits", "f1", 0).mkdir(parents=True)
    with pytest.raises(StoreError, match=r"seed-0\.json is a directory"):
        st.read_cell("limits", "f1", 0, "h")


def test_concurrent_sweep_wrote_the_same_model(tmp_path) -> None:
    st = ResultStore.open(tmp_path / "s", {"d": 1})
    first = st.write_model("pca", "h1", {"a.txt": b"1"}, {})
    assert st.write_model("pca", "h1", {"a.txt": b"2"}, {}) == first  # accepted, not an error
    assert (first / "a.txt").read_bytes() == b"1"
    with pytest.raises(StoreError, match=r"models/pca was trained with other diagnoser"):
        st.write_model("pca", "h2", {"a.txt": b"3"}, {})


def test_write_model_race_on_rename(tmp_path, monkeypatch) -> None:
    st = ResultStore.open(tmp_path / "s", {"d": 1})
    real_rename = os.rename

    def racing(src, dst):  # the other sweep renames its copy first
        other = ResultStore(st.root, st.data_hash)
        monkeypatch.setattr(os, "rename", real_rename)
        other.write_model("pca", "h1", {"a.txt": b"other"}, {})
        return real_rename(src, dst)

    monkeypatch.setattr(os, "rename", racing)
    final = st.write_model("pca", "h1", {"a.txt": b"mine"}, {})
    assert (final / "a.txt").read_bytes() == b"other"
    assert not list(final.parent.glob(".*.tmp"))


def test_stale_tmp_files_are_removed_on_open(tmp_path) -> None:
    st = ResultStore.open(tmp_path / "s", {"d": 1})
    cell_dir = st.cell_path("limits", "f1", 0).parent
    cell_dir.mkdir(parents=True)
    old, young = cell_dir / ".seed-0.json.abc.tmp", cell_dir / ".seed-1.json.def.tmp"
    old_model = st.root / "models" / ".pca.xyz.tmp"
    old_model.mkdir(parents=True)
    for p in (old, young):
        p.write_text("{")
    past = time.time() - 2 * 3600
    os.utime(old, (past, past))
    os.utime(old_model, (past, past))
    ResultStore.open(tmp_path / "s", {"d": 1})
    assert not old.exists() and not old_model.exists() and young.exists()


# ---- items 8, 10, 11: the sweep and the leaderboard CLI --------------------------------------
def _small_sweep():
    from evaluation.sweep import SimulatedData, SweepConfig, default_specs

    return SweepConfig(
        diagnosers=default_specs(("limits",)),
        data=SimulatedData(
            scenarios=("nominal",), test_seeds=(0,), train_seeds=(200,), n_samples=300
        ),
    )


def test_wrong_type_in_a_cell_file_is_reported_before_any_work(tmp_path, monkeypatch) -> None:
    from evaluation.sweep import runner as sweep

    cfg = _small_sweep()
    sweep.run_sweep(cfg, tmp_path / "s", n_workers=0, progress=False)
    cell = next((tmp_path / "s" / "cells").rglob("seed-0.json"))
    obj = json.loads(cell.read_text())
    obj["record"]["r_fd"] = "high"
    cell.write_text(json.dumps(obj))
    (tmp_path / "s" / "models" / "limits" / "spec.json").unlink()  # work would be to retrain
    (tmp_path / "s" / "models" / "limits").rename(tmp_path / "s" / "models" / ".old")
    monkeypatch.setattr(sweep, "make_backend", lambda *a: pytest.fail("work started"))
    with pytest.raises(ValueError, match=r"seed-0\.json: .*r_fd='high' has the wrong type"):
        sweep.run_sweep(cfg, tmp_path / "s", n_workers=0, progress=False)


def test_bad_hyperparameter_fails_before_training(tmp_path, monkeypatch) -> None:
    from evaluation.sweep import DiagnoserSpec
    from evaluation.sweep import runner as sweep

    cfg = _small_sweep()
    cfg = type(cfg)(diagnosers=(DiagnoserSpec("pca", {"alpha": 5}),), data=cfg.data)
    monkeypatch.setattr(sweep, "make_backend", lambda *a: pytest.fail("work started"))
    with pytest.raises(ValueError, match=r"diagnoser 'pca': alpha=5 is outside"):
        sweep.run_sweep(cfg, tmp_path / "s", n_workers=0, progress=False)


def _cli(args: list[str], capsys) -> tuple[int, str]:
    from evaluation.leaderboard import main

    with pytest.raises(SystemExit) as e:
        main([*args, "--no-progress", "--no-figures"])
    return e.value.code, capsys.readouterr().err


def test_cli_out_on_or_under_a_regular_file(tmp_path, capsys) -> None:
    f = tmp_path / "file.txt"
    f.write_text("x")
    code, err = _cli(["--quick", "--out", str(f)], capsys)
    assert code == 2 and f"--out '{f}' is a regular file" in err and "Traceback" not in err
    code, err = _cli(["--quick", "--out", str(f / "sub")], capsys)
    assert code == 2 and f"lies under '{f}', which is a regular file" in err


def test_cli_backend_ray_without_ray(tmp_path, capsys, monkeypatch) -> None:
    real_import = builtins.__import__

    def no_ray(name, *a, **kw):
        if name == "ray" or name.startswith("ray."):
            raise ImportError("No module named 'ray'")
        return real_import(name, *a, **kw)

    monkeypatch.setattr(builtins, "__import__", no_ray)
    code, err = _cli(["--quick", "--backend", "ray", "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "--backend ray needs Ray, which is not installed" in err
    assert not (tmp_path / "o").exists()


def test_cli_store_error_does_not_say_rerun(tmp_path, capsys, monkeypatch) -> None:
    from evaluation.leaderboard import paper

    def corrupted(opts):
        raise StoreError("/x/cells/seed-0.json is not valid JSON: delete it to recompute")

    monkeypatch.setattr(paper, "run", corrupted)
    code, err = _cli(["--quick", "--out", str(tmp_path / "o")], capsys)
    assert code == 1 and "seed-0.json is not valid JSON" in err and "re-run" not in err


# ---- item 10: external-data manifests --------------------------------------------------------
def _manifest(tmp_path: Path, **changes) -> Path:
    rng = np.random.default_rng(0)
    for name in ("train.csv", "test.csv"):
        y = rng.normal(size=(200, 2))
        (tmp_path / name).write_text("a,b\n" + "\n".join(f"{p},{q}" for p, q in y))
    spec = {
        "inputs": ["a"],
        "outputs": ["b"],
        "train_files": ["train.csv"],
        "test_files": [{"path": "test.csv", "onset": None}],
        "sample_time_s": 60,
        **changes,
    }
    (tmp_path / "dataset.json").write_text(json.dumps(spec))
    return tmp_path


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"inputs": "a"}, r"dataset\.json: inputs='a' is outside .* list of names"),
        ({"outputs": ["b", 3]}, r"dataset\.json: outputs=\['b', 3\] is outside"),
        ({"sample_time_s": "ten"}, r"dataset\.json: sample_time_s='ten' is outside"),
        (
            {"diagnoser_params": {"pca": {"alpha": "x"}}},
            r"dataset\.json: diagnoser_params\['pca'\]: alpha='x' is outside",
        ),
    ],
)
def test_bad_manifest(tmp_path, changes, match) -> None:
    from evaluation.sweep.dataset_loaders import load_manifest

    with pytest.raises(ValueError, match=match):
        load_manifest(_manifest(tmp_path, **changes))


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--block", "0"], "'0'; allowed: an integer >= 2"),
        (["--streaks", "-1"], "'-1'; allowed: an integer >= 0"),
        (["--n-healthy", "x"], "'x'; allowed: an integer >= 1"),
        (["--n-healthy", "20", "--block", "50"], "--block 50; allowed: at most --n-healthy (20)"),
        (["--set", "slow_ewma_lambda=[0.08"], "--set 'slow_ewma_lambda=[0.08'; allowed: key=value"),
        (["--set", "on_delay"], "--set 'on_delay'; allowed: key=value pairs with JSON values"),
    ],
)
def test_fd_tail_lab_refuses_bad_flags_by_value_and_range(args, message) -> None:
    _lab_refuses("fd_tail_lab.py", args, message)


def _lab_refuses(script: str, args: list[str], message: str) -> None:
    """The lab script exits with argparse's code 2 and ``message`` on stderr; the flags are
    checked before any bank is loaded or episode simulated."""
    root = Path(__file__).resolve().parents[1]
    done = subprocess.run(
        [sys.executable, str(root / "lab" / script), *args],
        capture_output=True,
        text=True,
        cwd=root,
        timeout=120,
    )
    assert done.returncode == 2
    assert message in done.stderr


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--track", "nope"], "--track 'nope'; allowed: one of"),
        (["--faults", "sensor-bias,f1"], "--faults ['f1']; allowed: classes of sensor"),
        ([], "lacks ['leaderboard.json', 'results.json']; allowed: a goal_table.py --out"),
    ],
)
def test_goal_channels_refuses_bad_flags_by_value_and_range(args, message, tmp_path) -> None:
    _lab_refuses("goal_channels.py", ["--out", str(tmp_path), *args], message)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--order", "0"], "'0'; allowed: an integer >= 1"),
        (["--window", "x"], "'x'; allowed: an integer >= 1"),
        (["--n-seeds", "-3"], "'-3'; allowed: an integer >= 1"),
        (["--shares", "0.004,1.5"], "'1.5'; allowed: numbers in (0, 1), comma-separated"),
        (["--shares", "a"], "'a'; allowed: numbers in (0, 1)"),
        (["--eval-tracks", "paper,tiny"], "--eval-tracks ['tiny']; allowed: paper, small"),
    ],
)
def test_whitened_glr_lab_refuses_bad_flags_by_value_and_range(args, message) -> None:
    _lab_refuses("whitened_glr_lab.py", args, message)


@pytest.mark.parametrize(
    ("script", "args", "message"),
    [
        ("input_noise_limit.py", ["--stages", "t2,cusum"], "--stages 'cusum'; allowed: ['t2'"),
        ("input_noise_limit.py", ["--target", "0.7"], "--target 0.7; allowed: a false-alarm"),
        ("input_noise_limit.py", ["--n-healthy", "0"], "'0'; allowed: an integer >= 1"),
        ("optimizer_lab.py", ["--variants", "adam:3000,sgd:5"], "'sgd:5'; allowed: adam:N or"),
        ("optimizer_lab.py", ["--variants", "lbfgs:0"], "'lbfgs:0'; allowed: adam:N or lbfgs:N"),
        ("optimizer_lab.py", ["--output", "T_d1"], "invalid choice: 'T_d1'"),
        ("optimizer_lab.py", ["--n-train", "1"], "'1'; allowed: an integer >= 2"),
        ("optimizer_lab.py", ["--val-fraction", "1"], "--val-fraction 1.0; allowed: a number in"),
        ("optimizer_lab.py", ["--val-fraction", "x"], "invalid float value: 'x'"),
        ("optimizer_lab.py", ["--seed", "-1"], "'-1'; allowed: an integer >= 0"),
        ("optimizer_lab.py", ["--hidden", "0"], "'0'; allowed: an integer >= 1"),
        ("optimizer_lab.py", ["--weight-decay", "-0.001"], "--weight-decay -0.001, --input-noise"),
        ("optimizer_lab.py", ["--input-noise", "-0.1"], "--input-noise -0.1; allowed: >= 0"),
        ("optimizer_lab.py", ["--train-inputs", "clean"], "invalid choice: 'clean'"),
        ("plant_mismatch_lab.py", ["--lags", "1,0.5"], "'1,0.5'; allowed: comma-separated"),
        ("plant_mismatch_lab.py", ["--lags", "x"], "'x'; allowed: comma-separated numbers >= 1"),
        ("plant_mismatch_lab.py", ["--ridge", "0"], "--ridge 0.0; allowed: a number > 0"),
        ("plant_mismatch_lab.py", ["--from", "300"], "'300'; allowed: an integer >= 301"),
        ("plant_mismatch_lab.py", ["--n-healthy", "0"], "'0'; allowed: an integer >= 1"),
    ],
)
def test_reference_and_optimizer_labs_refuse_bad_flags(script, args, message) -> None:
    _lab_refuses(script, args, message)
