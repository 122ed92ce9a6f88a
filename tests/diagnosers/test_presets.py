"""The LRGF variants are presets: the family class with other defaults, one mechanism."""

from __future__ import annotations

import inspect
from typing import ClassVar

import pytest

import diagnosers
from diagnosers.lrgf.bank_detector import BankDetector
from diagnosers.lrgf.lrgf_glr import LRGFGLR
from diagnosers.lrgf.lrgf_mem import LRGFMEM
from diagnosers.lrgf.lrgf_presets import PRESETS
from diagnosers.presets import keyword_init, preset

FAMILIES = {"lrgf-mem-paper": LRGFMEM, "lrgf-glr-adaptive": LRGFGLR, "lrgf-glr-closed": LRGFGLR}


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_a_preset_is_its_family_with_other_defaults(name: str) -> None:
    family = FAMILIES[name]
    variant = diagnosers.make(name)
    assert isinstance(variant, family) and type(variant).__mro__[1] is family
    assert variant.get_params() == family(**PRESETS[name]).get_params()
    # the same hyperparameters in the same order, and the user's value still wins
    assert type(variant).param_names() == family.param_names()
    if PRESETS[name]:  # lrgf-glr-closed changes only its relations (a class attribute)
        first = next(iter(PRESETS[name]))
        assert diagnosers.make(name, **{first: None}).get_params()[first] is None


@pytest.mark.parametrize("name", ["lrgf-mem", "lrgf-mem-paper", "lrgf-glr", "lrgf-glr-adaptive"])
def test_every_lrgf_detector_has_a_real_keyword_signature(name: str) -> None:
    cls = diagnosers.diagnoser_class(name)
    assert issubclass(cls, BankDetector)
    params = list(inspect.signature(cls.__init__).parameters.values())[1:]
    assert params and all(p.kind is p.KEYWORD_ONLY for p in params)
    assert set(cls.fast_params()) <= set(cls.param_names())
    # one word per concept: the drawn band's level says what it moves
    assert "band_alpha" in cls.param_names() and "alpha" not in cls.param_names()


def test_false_alarm_target_is_one_hyperparameter_of_each_alarm_stage() -> None:
    targets = {n: diagnosers.make(n).get_params()["false_alarm_target"] for n in FAMILIES}
    assert targets == {
        "lrgf-mem-paper": 0.002,
        "lrgf-glr-adaptive": 0.04,
        "lrgf-glr-closed": 0.025,
    }
    assert LRGFGLR().false_alarm_target == 0.025


def test_defaults_are_copied_per_instance_and_unknown_names_refused() -> None:
    class Demo:
        DEFAULTS: ClassVar[dict[str, list[int]]] = {"a": [1]}
        __init__ = keyword_init(DEFAULTS)

    one, two = Demo(), Demo()
    one.a.append(2)
    assert two.a == [1] and Demo.DEFAULTS["a"] == [1]
    with pytest.raises(TypeError, match=r"unknown hyperparameter\(s\) \['b'\]"):
        Demo(b=1)
    with pytest.raises(ValueError, match=r"\['nope'\] are not hyperparameters"):
        preset("x-test", LRGFMEM, {"nope": 1}, "doc", module=__name__)
