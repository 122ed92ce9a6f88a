"""Plugging in: episodes from data in one call, set_params, the registry's plug-in routes,
progress, versions and the console scripts."""

from __future__ import annotations

import dataclasses
import importlib
import json
import sys
import textwrap
import tomllib
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest
from synthetic import make_episode

import diagnosers
import evaluation
import fcc_env
from diagnosers import Episode, NotFittedError, registry
from diagnosers.networks.optimisers import auto_progress
from fcc_env.generate import write_dataset

ROOT = Path(__file__).resolve().parents[2]


# ---- Episode.from_batch ------------------------------------------------------------------------
@pytest.fixture(scope="module")
def batch() -> fcc_env.BatchResult:
    return fcc_env.simulate_episodes([3, 4], 200, fault=fcc_env.FaultSpec(scenario="f1", onset=120))


def test_from_batch_carries_labels_and_clean_data(batch) -> None:
    eps = Episode.from_batch(batch)
    assert [ep.seed for ep in eps] == [3, 4]
    for b, ep in enumerate(eps):
        assert ep.scenario == "f1" and ep.fault_onset == 120
        assert ep.channels == tuple(fcc_env.MEASUREMENT_NAMES)
        assert ep.sample_time_s == batch.sample_time_s
        np.testing.assert_array_equal(ep.y, batch.observations[b].astype(np.float64))
        np.testing.assert_array_equal(ep.y_clean, batch.y_clean[b])


def test_from_batch_cuts_at_termination(batch) -> None:
    # episode 0 "terminated" at 150 (after the onset), episode 1 at 100 (before it)
    cut = dataclasses.replace(batch, terminated_at=np.array([150, 100]))
    first, second = Episode.from_batch(cut)
    assert first.n_samples == 150 and first.fault_onset == 120
    assert second.n_samples == 100 and second.fault_onset is None  # the fault never came
    assert second.y_clean.shape == (100, 8)


def test_from_batch_healthy_and_bad_shape() -> None:
    [ep] = Episode.from_batch(fcc_env.simulate_episodes([0], 50))
    assert ep.fault_onset is None and ep.scenario == "nominal"
    bad = dataclasses.replace(
        fcc_env.simulate_episodes([0], 50), observations=np.zeros((50, 8), np.float32)
    )
    with pytest.raises(ValueError, match=r"got \(50, 8\)"):
        Episode.from_batch(bad)


def test_from_batch_feeds_fit_and_matches_the_harness(batch) -> None:
    from evaluation.sweep.sources import simulate_loaded
    from fcc_env.scenarios import FaultSpec

    det = diagnosers.make("limits").fit(Episode.from_batch(batch))
    assert det.channels_ == tuple(fcc_env.MEASUREMENT_NAMES)
    loaded = simulate_loaded([3], 200, FaultSpec(scenario="f1", onset=120))[0]
    np.testing.assert_array_equal(loaded.episode.y, Episode.from_batch(batch)[0].y)


# ---- Episode.from_dataset ----------------------------------------------------------------------
def test_from_dataset_gives_one_episode_per_seed(tmp_path, batch) -> None:
    path = write_dataset(tmp_path / "d.csv", scenario="f1", seeds=[3, 4], n_samples=200,
                         fault_time=120)  # fmt: skip
    eps = Episode.from_dataset(path)
    assert [(ep.seed, ep.scenario, ep.fault_onset, ep.n_samples) for ep in eps] == [
        (3, "f1", 120, 200),
        (4, "f1", 120, 200),
    ]
    for b, ep in enumerate(eps):
        assert ep.channels == tuple(fcc_env.MEASUREMENT_NAMES)
        np.testing.assert_allclose(ep.y, batch.observations[b], rtol=1e-9)
        np.testing.assert_allclose(ep.y_clean, batch.y_clean[b], rtol=1e-9)


def test_from_dataset_honours_terminated_at(tmp_path) -> None:
    path = write_dataset(tmp_path / "d.csv", scenario="f2", seeds=[0, 1], n_samples=100,
                         fault_time=80)  # fmt: skip
    sidecar = path.with_suffix(".json")
    meta = json.loads(sidecar.read_text())
    meta["terminated_at"] = [60, None]
    sidecar.write_text(json.dumps(meta))
    first, second = Episode.from_dataset(path)
    assert (first.n_samples, first.fault_onset) == (60, None)
    assert (second.n_samples, second.fault_onset) == (100, 80)


def test_from_dataset_errors_name_the_problem(tmp_path) -> None:
    path = write_dataset(tmp_path / "d.csv", seeds=[0], n_samples=20)
    with pytest.raises(ValueError, match=r"missing\.csv' does not exist"):
        Episode.from_dataset(tmp_path / "missing.csv")
    sidecar = path.with_suffix(".json")
    meta = json.loads(sidecar.read_text())
    meta["roles"]["measured"] = ["T_rx", "T_nope"]
    sidecar.write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=r"missing \['T_nope'\]"):
        Episode.from_dataset(path)
    meta["roles"]["measured"] = ["T_rx"]
    del meta["sample_time_s"]
    sidecar.write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="no sample_time_s"):
        Episode.from_dataset(path)


# ---- Episode.from_frame ------------------------------------------------------------------------
def test_from_frame_without_pandas_says_how_to_fix(monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "pandas", None)  # import pandas -> ImportError
    with pytest.raises(ImportError, match=r"needs pandas.*pip install pandas"):
        Episode.from_frame(object(), sample_time_s=10.0)


def test_from_frame_with_pandas() -> None:
    pd = pytest.importorskip("pandas")
    df = pd.DataFrame({"a": [1.0, 2.0, 3.0], "b": [4, 5, 6], "note": ["x", "y", "z"]})
    ep = Episode.from_frame(df, channels=["b", "a"], sample_time_s=5.0, fault_onset=1, seed=7)
    assert ep.channels == ("b", "a") and ep.fault_onset == 1 and ep.seed == 7
    np.testing.assert_array_equal(ep.y, [[4, 1], [5, 2], [6, 3]])
    with pytest.raises(ValueError, match=r"channels \['c'\] are not columns"):
        Episode.from_frame(df, channels=["a", "c"], sample_time_s=5.0)
    with pytest.raises(ValueError, match="must hold numbers"):
        Episode.from_frame(df, sample_time_s=5.0)
    with pytest.raises(TypeError, match="must be a pandas DataFrame, got list"):
        Episode.from_frame([[1.0]], sample_time_s=5.0)


# ---- set_params --------------------------------------------------------------------------------
def test_set_params_returns_self_checks_names_and_unfits() -> None:
    det = diagnosers.make("limits").fit([make_episode(200, 0)])
    assert det.set_params(alpha=0.05) is det and det.get_params()["alpha"] == 0.05
    with pytest.raises(NotFittedError):  # learned state belonged to the old alpha
        det.reset()
    with pytest.raises(ValueError, match=r"Unknown hyperparameter\(s\) \['alpah'\].*'limits'"):
        det.set_params(alpah=0.1)
    det.set_params(alpha=2.0)  # values are checked at fit, as for __init__
    with pytest.raises(ValueError, match=r"alpha=2\.0 is outside the allowed range"):
        det.fit([make_episode(200, 0)])


def test_set_params_without_arguments_keeps_the_fit() -> None:
    det = diagnosers.make("limits").fit([make_episode(200, 0)])
    assert det.set_params() is det
    det.reset()  # still fitted


# ---- registry plug-ins -------------------------------------------------------------------------
PLUGIN_SOURCE = """
import numpy as np
from diagnosers import Diagnoser


class EntryPointDetector(Diagnoser):
    def __init__(self, *, gain: float = 1.0) -> None:
        self.gain = gain

    def _fit(self, episodes):
        self.signal_names_ = ("zero",)

    def _reset(self):
        pass

    def _update(self, y):
        from diagnosers import Decision
        z = np.zeros(1)
        return Decision(False, z, z - 1, z + 1, z)

    def _get_state(self):
        return {}

    def _set_state(self, state):
        self.signal_names_ = ("zero",)
"""


@pytest.fixture
def plugin_module(tmp_path, monkeypatch):
    (tmp_path / "fcc_test_plugin_mod.py").write_text(textwrap.dedent(PLUGIN_SOURCE))
    monkeypatch.syspath_prepend(str(tmp_path))
    saved = dict(registry._REGISTRY)
    yield "fcc_test_plugin_mod"
    registry._REGISTRY.clear()
    registry._REGISTRY.update(saved)
    registry._ENTRY_POINTS_LOADED = False
    sys.modules.pop("fcc_test_plugin_mod", None)


def _entry_points(*eps: metadata.EntryPoint):
    def fake(*, group: str):
        assert group == registry.ENTRY_POINT_GROUP
        return metadata.EntryPoints(eps)

    return fake


def test_entry_points_are_loaded_lazily(plugin_module, monkeypatch) -> None:
    good = metadata.EntryPoint(
        name="ep-det", value=f"{plugin_module}:EntryPointDetector", group=registry.ENTRY_POINT_GROUP
    )
    broken = metadata.EntryPoint(
        name="broken-det", value="no_such_module_xyz:Nope", group=registry.ENTRY_POINT_GROUP
    )
    monkeypatch.setattr(registry.metadata, "entry_points", _entry_points(good, broken))
    registry._ENTRY_POINTS_LOADED = False
    with pytest.warns(RuntimeWarning, match="'broken-det' = 'no_such_module_xyz:Nope' failed"):
        det = diagnosers.make("ep-det", gain=2.0)
    assert det.name == "ep-det" and det.get_params() == {"gain": 2.0}
    assert "ep-det" in diagnosers.available() and "broken-det" not in diagnosers.available()


def test_import_modules_registers_and_names_a_bad_module(plugin_module) -> None:
    mod = importlib.import_module(plugin_module)
    diagnosers.register("imported-det")(mod.EntryPointDetector)
    diagnosers.import_modules([plugin_module])  # already imported: no second registration
    assert diagnosers.diagnoser_class("imported-det") is mod.EntryPointDetector
    with pytest.raises(ValueError, match=r"cannot import module 'no_such_module_xyz'"):
        diagnosers.import_modules(["no_such_module_xyz"])
    with pytest.raises(ValueError, match=r"module='' is outside the allowed range"):
        diagnosers.import_modules([""])


def test_unknown_name_says_how_to_register() -> None:
    with pytest.raises(ValueError, match=r"Unknown diagnoser 'mine'.*--import MODULE"):
        diagnosers.make("mine")


def test_sweep_config_rejects_bad_imports() -> None:
    from evaluation.sweep import SweepConfig, default_specs

    cfg = SweepConfig(diagnosers=default_specs(["limits"]), imports="examples")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"imports='examples' is outside the allowed range"):
        cfg.validate()
    cfg = SweepConfig(diagnosers=default_specs(["limits"]), imports=("no_such_module_xyz",))
    with pytest.raises(ValueError, match="cannot import module 'no_such_module_xyz'"):
        cfg.validate()


# ---- progress, versions, packaging -------------------------------------------------------------
class _Stream:
    def __init__(self, tty: bool) -> None:
        self.tty = tty

    def isatty(self) -> bool:
        return self.tty

    def write(self, text: str) -> int:
        return len(text)

    def flush(self) -> None:
        pass


def test_auto_progress_follows_the_terminal(monkeypatch) -> None:
    monkeypatch.setattr(sys, "stderr", _Stream(False))
    assert auto_progress(None) is False and auto_progress(True) is True
    monkeypatch.setattr(sys, "stderr", _Stream(True))
    assert auto_progress(None) is True and auto_progress(False) is False


def test_lrgf_mem_progress_defaults_to_auto() -> None:
    det = diagnosers.make("lrgf-mem")
    assert det.get_params()["progress"] is None
    det.set_params(progress="yes")
    with pytest.raises(ValueError, match=r"progress='yes' is outside the allowed range"):
        det.validate_params()


def test_one_version_everywhere() -> None:
    assert diagnosers.__version__ == evaluation.__version__ == fcc_env.__version__
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert pyproject["project"]["dynamic"] == ["version"]
    assert pyproject["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "fcc_env.__version__"}
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        _ = evaluation.nope  # type: ignore[attr-defined]


def test_py_typed_markers_are_shipped() -> None:
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    data = pyproject["tool"]["setuptools"]["package-data"]
    for pkg in ("fcc_env", "diagnosers", "evaluation"):
        assert (ROOT / pkg / "py.typed").is_file()
        assert data[pkg] == ["py.typed"]


def test_console_scripts_point_at_mains(capsys) -> None:
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert set(scripts) == {"fcc-leaderboard", "fcc-generate", "fcc-discover", "fcc-demo"}
    for name, target in scripts.items():
        module, func = target.split(":")
        main = getattr(importlib.import_module(module), func)
        with pytest.raises(SystemExit) as exc:  # --help: parses, prints usage, exits 0
            main(["--help"])
        assert exc.value.code == 0, name
    assert "usage:" in capsys.readouterr().out


def test_reset_is_documented() -> None:
    from fcc_env.env import RESET_OPTION_NAMES, FCCEnv

    doc = FCCEnv.reset.__doc__
    assert doc is not None and "Returns:" in doc
    for key in RESET_OPTION_NAMES:
        assert f"``{key}``" in doc, key


def test_cli_import_finds_modules_in_the_current_directory(tmp_path, monkeypatch) -> None:
    """A console script (``fcc-leaderboard``) does not put the current directory on sys.path;
    ``--import`` does, as ``python -m`` would, so a module beside the user is found."""
    from evaluation.leaderboard.arguments import build_parser, import_user_modules

    (tmp_path / "fcc_cwd_plugin_mod.py").write_text("LOADED = True\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])
    monkeypatch.delitem(sys.modules, "fcc_cwd_plugin_mod", raising=False)
    parser = build_parser()
    args = parser.parse_args(["--import", "fcc_cwd_plugin_mod", "--import", "fcc_cwd_plugin_mod"])
    assert args.imports == [("fcc_cwd_plugin_mod",), ("fcc_cwd_plugin_mod",)]
    import_user_modules(args, parser)
    assert sys.modules["fcc_cwd_plugin_mod"].LOADED and sys.path[0] == str(tmp_path)
    sys.modules.pop("fcc_cwd_plugin_mod")
