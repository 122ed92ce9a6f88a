"""The bank's file format (``diagnosers.networks.modules.save_bank`` / ``load_bank``) and the CSV writer
every results table goes through (``evaluation.reports.outputs.write_csv``)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
import torch

import diagnosers
import fcc_env
from diagnosers.networks.modules import load_bank, paper_lrgf, paper_mem, save_bank
from evaluation.reports.outputs import write_csv


def _bank() -> list[dict]:
    return [{"lrgf": paper_lrgf(seed=s), "mem": paper_mem(seed=s)} for s in (0, 1)]


def test_a_bank_comes_back_with_the_same_weights_in_evaluation_mode(tmp_path: Path) -> None:
    bank = _bank()
    save_bank(tmp_path, bank)
    loaded = load_bank(tmp_path)
    assert [sorted(p) for p in loaded] == [["lrgf", "mem"], ["lrgf", "mem"]]
    for saved, back in zip(bank, loaded, strict=True):
        for part, module in saved.items():
            assert type(back[part]) is type(module) and not back[part].training
            for k, v in module.state_dict().items():
                assert torch.equal(back[part].state_dict()[k], v), (part, k)
    # relation 1's networks are not relation 0's: the prefixes keep them apart
    a, b = (p["lrgf"].state_dict() for p in loaded)
    assert any(not torch.equal(a[k], b[k]) for k in a)


def test_a_bank_file_that_does_not_match_its_weights_is_refused_by_name(tmp_path: Path) -> None:
    save_bank(tmp_path, _bank())
    configs = json.loads((tmp_path / "models.json").read_text())
    configs[0]["lrgf"]["n_hidden"] = 7  # the weights are for 3 neurons
    (tmp_path / "models.json").write_text(json.dumps(configs))
    with pytest.raises(ValueError, match="do not describe a valid model"):
        load_bank(tmp_path)
    (tmp_path / "weights.pt").write_bytes(b"not a torch file")
    with pytest.raises(ValueError, match=r"weights\.pt is not a valid model file"):
        load_bank(tmp_path)
    (tmp_path / "models.json").unlink()
    with pytest.raises(ValueError, match=r"models\.json is missing"):
        load_bank(tmp_path)


def test_a_saved_diagnoser_missing_a_part_of_a_relation_is_refused(tmp_path: Path) -> None:
    det = diagnosers.make("lrgf-mem-paper", max_epochs=2, mem_max_epochs=2)
    batch = fcc_env.simulate_episodes([1000, 1001], 400)
    det.fit(diagnosers.Episode.from_batch(batch))
    path = det.save(tmp_path / "model")
    configs = json.loads((path / "models.json").read_text())
    del configs[0]["mem"]
    (path / "models.json").write_text(json.dumps(configs))
    with pytest.raises(ValueError, match="lacks the 'mem' part"):
        diagnosers.Diagnoser.load(path)


def test_write_csv_takes_every_key_in_order_and_leaves_missing_values_empty(
    tmp_path: Path,
) -> None:
    rows = [{"a": 1, "b": float("nan")}, {"b": 2.5, "c": None, "a": 3}]
    path = write_csv(tmp_path / "t.csv", rows)
    with path.open(newline="") as fh:
        back = list(csv.reader(fh))
    assert back == [["a", "b", "c"], ["1", "", ""], ["3", "2.5", ""]]
    write_csv(tmp_path / "u.csv", rows, ["c", "a", "b"])
    assert (tmp_path / "u.csv").read_text().splitlines()[0] == "c,a,b"
    assert not list(tmp_path.glob("*.tmp*"))  # written atomically, nothing left behind
