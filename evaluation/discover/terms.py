"""Candidate terms of a proposed form, and the form itself: a sparse correction of one equation.

A *form* (:class:`FormCandidate`) adds ``Σ_k θ_k·term_k`` to one equation of the declared FCC
model: a state equation (``dT_rg2/dt += …``, per second, in the state's unit) or a
measurement (``T_rg1 += …``, in the channel's unit). A :class:`Term` is a product of up to three
:class:`Factor` s; a factor is a simple function of one *signal* of the model, centred and scaled,
``fn((z − center)/scale)``, optionally of the signal's first-order lag. Signals are the model's
states, its inputs and its riser outlet temperature (:data:`SIGNALS`): everything a term may be
built from while the model is simulated.

:class:`TermLibrary` builds the candidates (constant, each signal through each function, products
of pairs, lags) and takes user terms (``extra``); a new function is one row of
:data:`FUNCTIONS` here and one branch of :func:`evaluation.discover.corrected_sim.factor_value`.
The fitted form is rendered as an equation a person reads (:func:`equation`), with a linear term
and a constant merged into ``θ·(z − z₀)``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from evaluation.discover.base import ParamInfo
from fcc_common.validation import Options, Real, check, invalid
from fcc_env.params import INPUT_NAMES, INPUT_UNITS, STATE_UNITS

__all__ = [
    "FUNCTIONS",
    "N_BASE_SIGNALS",
    "SIGNALS",
    "SIGNAL_UNITS",
    "STATE_TARGETS",
    "Factor",
    "FormCandidate",
    "Term",
    "TermLibrary",
    "equation",
    "form_from_json",
    "form_to_json",
    "shape_slots",
]

#: Model signals a factor may use: the 11 states (measured temperatures under their Table 1
#: names), the 6 inputs, and the riser outlet temperature T_rx (an algebraic output).
SIGNALS: tuple[str, ...] = (
    "W_rx",
    "C_sc",
    "W1",
    "C1",
    "T_rg1",
    "W2",
    "C2",
    "T_rg2",
    "W_sp",
    "T_d1",
    "T_dg",
    *INPUT_NAMES,
    "T_rx",
)
SIGNAL_UNITS: dict[str, str] = dict(zip(SIGNALS, (*STATE_UNITS, *INPUT_UNITS, "°C"), strict=True))
N_BASE_SIGNALS = len(SIGNALS)
#: State equations a form may enter (state name → index in the state vector).
STATE_TARGETS: dict[str, int] = {s: i for i, s in enumerate(SIGNALS[:11])}
#: Function codes of a factor (the compiled kernel's switch).
FUNCTIONS: dict[str, int] = {
    "lin": 0,
    "sq": 1,
    "cube": 2,
    "tanh": 3,
    "pos": 4,
    "abs": 5,
    "exp": 6,
}
_POWER = {"lin": 1, "sq": 2, "cube": 3}


@dataclass(frozen=True)
class Factor:
    """``fn((z − center)/scale)`` of signal ``z`` (its first-order lag when ``lag_s`` > 0)."""

    signal: str
    fn: str = "lin"
    center: float = 0.0
    scale: float = 1.0
    lag_s: float = 0.0

    def __post_init__(self) -> None:
        check("signal", self.signal, Options(SIGNALS))
        check("fn", self.fn, Options(tuple(FUNCTIONS)))
        check("center", self.center, Real())
        check("scale", self.scale, Real(0.0, math.inf, closed="neither"))
        check("lag_s", self.lag_s, Real(0.0, math.inf, closed="left"))

    def text(self) -> str:
        """The factor in natural units, without its scale where the scale is a pure factor."""
        z = self.signal if self.lag_s == 0 else f"lag{round(self.lag_s, 1):g}s({self.signal})"
        dz = z if self.center == 0 else f"({z} − {_num(self.center)})"
        if self.fn in _POWER:
            p = _POWER[self.fn]
            return dz if p == 1 else f"{dz}{'²' if p == 2 else '³'}"
        if self.fn in ("tanh", "exp"):  # the scale is part of the shape: shown with its unit
            u = SIGNAL_UNITS[self.signal]
            dz = z if self.center == 0 else f"({z} − {_num(self.center)} {u})"
            return f"{self.fn}({dz}/{_num(self.scale)} {u})"
        if self.fn == "pos":
            return f"max({dz}, 0)"
        return f"|{dz}|"

    def natural_scale(self) -> float:
        """What ``θ`` must be divided by to multiply :meth:`text` instead of the scaled factor."""
        if self.fn in _POWER:
            return self.scale ** _POWER[self.fn]
        return 1.0 if self.fn in ("tanh", "exp") else self.scale

    def unit(self) -> str:
        u = SIGNAL_UNITS[self.signal]
        if self.fn in _POWER and _POWER[self.fn] > 1:
            return f"{u}{'²' if _POWER[self.fn] == 2 else '³'}"
        return "" if self.fn in ("tanh", "exp") else u


@dataclass(frozen=True)
class Term:
    """A product of up to three factors (none: the constant 1)."""

    factors: tuple[Factor, ...] = ()

    def __post_init__(self) -> None:
        if len(self.factors) > 3:
            raise invalid("factors", len(self.factors), "at most 3 factors per term")

    def text(self) -> str:
        return "·".join(f.text() for f in self.factors) if self.factors else "1"

    def natural_scale(self) -> float:
        return float(np.prod([f.natural_scale() for f in self.factors])) if self.factors else 1.0

    def unit(self) -> str:
        units = [u for f in self.factors if (u := f.unit())]
        return "·".join(units)

    @property
    def lags(self) -> tuple[tuple[str, float], ...]:
        return tuple((f.signal, f.lag_s) for f in self.factors if f.lag_s > 0)


def _num(v: float) -> str:
    return f"{v:.4g}"


@dataclass(frozen=True)
class TermLibrary:
    """Which candidate terms a form is selected from (user-extensible).

    ``signals`` through each of ``functions``; products of pairs of ``signals`` (centred, scaled
    linear factors) when ``products``; the linear lag of each signal by each of ``lags_s``
    seconds; a constant when ``constant``; and any user ``extra`` terms (their centres and
    scales are used as given). Centres and scales of the built terms come from the training
    part of the declared model's simulation (mean and standard deviation of each signal).
    """

    signals: tuple[str, ...] = (
        "T_rg1",
        "T_rg2",
        "T_d1",
        "T_dg",
        "T_rx",
        "u_F",
        "R_ar",
        "T_ar",
        "T_fp",
        "C2",
    )
    functions: tuple[str, ...] = ("lin", "sq", "tanh")
    products: bool = True
    lags_s: tuple[float, ...] = (300.0, 1200.0)
    constant: bool = True
    extra: tuple[Term, ...] = field(default=())

    def __post_init__(self) -> None:
        for s in self.signals:
            check("signal", s, Options(SIGNALS))
        for f in self.functions:
            check("function", f, Options(tuple(FUNCTIONS)))
        for t in self.extra:
            if not isinstance(t, Term):
                raise invalid("extra", t, "Term objects")

    def build(self, centers: dict[str, float], scales: dict[str, float]) -> tuple[Term, ...]:
        """The candidate terms with the given signal centres and scales."""

        def fac(s: str, fn: str = "lin", lag: float = 0.0) -> Factor:
            return Factor(s, fn, float(centers[s]), float(scales[s]), lag)

        out: list[Term] = [Term()] if self.constant else []
        out += [Term((fac(s, fn),)) for s in self.signals for fn in self.functions]
        if self.products:
            out += [
                Term((fac(a), fac(b)))
                for i, a in enumerate(self.signals)
                for b in self.signals[i + 1 :]
            ]
        out += [Term((fac(s, "lin", lag),)) for lag in self.lags_s for s in self.signals]
        out += list(self.extra)
        return tuple(out)


@dataclass(frozen=True)
class FormCandidate:
    """A proposed form: ``Σ θ_k·terms[k]`` added to equation ``target``.

    ``target``: a state name of :data:`STATE_TARGETS` (the term is a rate, state unit per
    second) or ``"y:<channel>"`` (added to the model's measurement of a Table 1 channel).
    It is a :class:`~evaluation.discover.base.Candidate` (``id``, ``params``): the loop fits,
    scores and accepts it as it does a library effect.
    """

    target: str
    terms: tuple[Term, ...]
    params: tuple[ParamInfo, ...]
    id: str = ""

    def __post_init__(self) -> None:
        if not self.is_measurement and self.target not in STATE_TARGETS:
            raise invalid("target", self.target, f"one of {list(STATE_TARGETS)} or 'y:<channel>'")
        if len(self.params) != len(self.terms):
            raise invalid("params", len(self.params), f"one per term ({len(self.terms)})")
        if not self.id:
            object.__setattr__(self, "id", f"form:{self.target}[{'+'.join(self.labels())}]")

    @property
    def is_measurement(self) -> bool:
        return self.target.startswith("y:")

    @property
    def channel(self) -> str:
        return self.target[2:] if self.is_measurement else self.target

    def labels(self) -> list[str]:
        return [t.text() for t in self.terms]

    @property
    def rate_unit(self) -> str:
        u = SIGNAL_UNITS.get(self.channel, "")
        return u if self.is_measurement else f"{u}/s"


#: Functions whose centre sets the shape (for "exp" the centre only rescales the coefficient).
_CENTERED = ("tanh", "sq", "cube", "pos", "abs")
_SHAPE_NAMES = {"center": "centre", "scale": "scale", "lag_s": "time constant"}


def shape_slots(form: FormCandidate) -> list[tuple[int, int, str]]:
    """The shape parameters of ``form``: (term, factor, ``Factor`` field) of every centre of a
    nonlinear factor or of a product's linear factor, every scale of a tanh or exp, and every
    lag's time constant; and, in a form without a constant term, the centre of its first linear
    term (the form's offset: without it, a saturation's centre would have to stand in for the
    offset). A form's coefficients do not reach these (they are nonlinear in them)."""
    out: list[tuple[int, int, str]] = []
    # without a constant term, the first linear term's centre is the form's offset
    offset = not any(not t.factors for t in form.terms)
    for i, t in enumerate(form.terms):
        for j, f in enumerate(t.factors):
            lin_offset = offset and f.fn == "lin" and len(t.factors) == 1
            if f.fn in _CENTERED or (f.fn == "lin" and len(t.factors) > 1) or lin_offset:
                out.append((i, j, "center"))
                offset = offset and not lin_offset
            if f.fn in ("tanh", "exp"):
                out.append((i, j, "scale"))
            if f.lag_s > 0:
                out.append((i, j, "lag_s"))
    return out


def equation(form: FormCandidate, theta: Sequence[float]) -> dict[str, object]:
    """The fitted form as text and parts: ``"dT_rg2/dt [°C/s] += −1.2e-05·(T_rg2 − 25.02)"``.

    Coefficients are given per natural unit of their term (``θ_k / scale^p``); a constant and a
    linear term of the same signal are merged into ``a·(z − z₀)``. ``shapes`` lists the value
    and unit of every shape parameter (:func:`shape_slots`): fitted where the search kept its
    shape fit, else as the library built it (a signal's training mean and sd, a lag's time
    constant).
    """
    th = np.asarray(theta, float)
    coef = [float(c / t.natural_scale()) for c, t in zip(th, form.terms, strict=True)]
    parts: list[tuple[float, str, str]] = []
    const_i = next((i for i, t in enumerate(form.terms) if not t.factors), None)
    lin = [
        i
        for i, t in enumerate(form.terms)
        if len(t.factors) == 1 and t.factors[0].fn == "lin" and t.factors[0].lag_s == 0
    ]
    used: set[int] = set()
    if const_i is not None and len(lin) == 1 and coef[lin[0]] != 0:
        f = form.terms[lin[0]].factors[0]
        z0 = f.center - coef[const_i] / coef[lin[0]]
        parts.append((coef[lin[0]], f"({f.signal} − {_num(z0)})", f.unit()))
        used = {const_i, lin[0]}
    for i, t in enumerate(form.terms):
        if i not in used:
            parts.append((coef[i], t.text(), t.unit()))
    lhs = f"{form.channel}" if form.is_measurement else f"d{form.channel}/dt"

    def part(k: int, c: float, txt: str) -> str:
        sign = ("− " if c < 0 else "+ ") if k else ("−" if c < 0 else "")
        return f"{sign}{abs(c):.3g}" + ("" if txt == "1" else f"·{txt}")

    body = " ".join(part(k, c, txt) for k, (c, txt, _) in enumerate(parts))
    unit = form.rate_unit
    shapes = []
    for i, j, kind in shape_slots(form):
        f = form.terms[i].factors[j]
        shapes.append(
            {
                "term": form.terms[i].text(),
                "signal": f.signal,
                "parameter": _SHAPE_NAMES[kind],
                "value": float(getattr(f, kind)),
                "unit": "s" if kind == "lag_s" else SIGNAL_UNITS[f.signal],
            }
        )
    return {
        "text": f"{lhs} [{unit}] += {body}",
        "enters": (
            f"the measurement of {form.channel}"
            if form.is_measurement
            else f"the state equation of {form.channel}"
        ),
        "unit": unit,
        "terms": [
            {"term": txt, "coefficient": c, "unit": f"{unit} per {u}" if u else unit}
            for c, txt, u in parts
        ],
        "shapes": shapes,
    }


def form_to_json(form: FormCandidate) -> dict[str, Any]:
    """The form's definition (target, terms with their centres and scales), as JSON: what
    :func:`form_from_json` reads back to accept it into the model."""
    return {
        "target": form.target,
        "terms": [[dataclasses.asdict(f) for f in t.factors] for t in form.terms],
    }


def form_from_json(d: Mapping[str, Any], form_id: str = "") -> FormCandidate:
    """A form from :func:`form_to_json`'s dict (bad fields are refused by name)."""
    try:
        terms = tuple(Term(tuple(Factor(**f) for f in t)) for t in d["terms"])
        target = str(d["target"])
    except (KeyError, TypeError) as e:
        raise ValueError(f"not a form definition ({e}): {dict(d)!r}") from e
    params = tuple(ParamInfo(f"c{i}", 1.0, -math.inf, math.inf) for i in range(len(terms)))
    return FormCandidate(target, terms, params, form_id)
