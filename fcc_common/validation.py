"""Declarative parameter constraints with one error format, shared by every package.

In the spirit of scikit-learn's ``_parameter_constraints``: a parameter is checked against a
constraint object (:class:`Integer`, :class:`Real`, :class:`Options`, :class:`Boolean`,
:class:`IntegerSequence`...) by :func:`check`, which returns the value in its canonical Python
type or raises ``ValueError`` with the one message format of the project::

    <name>=<value!r> is outside the allowed range: <what is allowed>[ (<why>)]

so every message names the value and the allowed range, whichever layer raises it. A layer that
owns a range declares it once as a constant and the others import it, so the ranges agree.

>>> check("rk4_substeps", 4, Integer(1, 100))
4
>>> check("noise_scale", 2, Real(0, 100))
2.0
>>> check("fault_profile", "ramp", Options(["abrupt", "incipient"]))
Traceback (most recent call last):
...
ValueError: fault_profile='ramp' is outside the allowed range: one of ['abrupt', 'incipient']
>>> check("sample_time_s", 0.1, Real(0.5, 60, unit="s"))
Traceback (most recent call last):
...
ValueError: sample_time_s=0.1 is outside the allowed range: a number in [0.5, 60] s
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from enum import Enum
from typing import Any

import numpy as np

__all__ = [
    "Boolean",
    "Constraint",
    "Integer",
    "IntegerSequence",
    "OptionSequence",
    "Options",
    "Real",
    "RealSequence",
    "check",
    "check_params",
    "from_fields",
    "invalid",
]


def invalid(name: str, value: Any, allowed: str, why: str | None = None) -> ValueError:
    """The project's one error for a bad value: names the value and what is allowed."""
    text = f"{name}={value!r} is outside the allowed range: {allowed}"
    if why:
        text += f" ({why})"
    return ValueError(text)


def _fmt(x: float) -> str:
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return f"{x:g}" if isinstance(x, float) else str(x)


class Constraint:
    """Base class: :meth:`coerce` returns the canonical value or raises via :func:`invalid`."""

    why: str | None = None

    def describe(self) -> str:  # pragma: no cover - abstract
        raise NotImplementedError

    def coerce(self, name: str, value: Any) -> Any:  # pragma: no cover - abstract
        raise NotImplementedError


def _is_int(v: Any) -> bool:
    return isinstance(v, int | np.integer) and not isinstance(v, bool | np.bool_)


def _is_real(v: Any) -> bool:
    return isinstance(v, int | float | np.integer | np.floating) and not isinstance(
        v, bool | np.bool_
    )


@dataclass(frozen=True)
class _Interval(Constraint):
    low: float = -math.inf
    high: float = math.inf
    closed: str = "both"  # "both", "left", "right", "neither"
    unit: str | None = None
    why: str | None = None

    def _range(self) -> str:
        left = "[" if self.closed in ("both", "left") and math.isfinite(self.low) else "("
        right = "]" if self.closed in ("both", "right") and math.isfinite(self.high) else ")"
        text = f"{left}{_fmt(self.low)}, {_fmt(self.high)}{right}"
        return f"{text} {self.unit}" if self.unit else text

    def _inside(self, v: float) -> bool:
        lo_ok = v >= self.low if self.closed in ("both", "left") else v > self.low
        hi_ok = v <= self.high if self.closed in ("both", "right") else v < self.high
        return lo_ok and hi_ok


@dataclass(frozen=True)
class Integer(_Interval):
    """An integer (Python or numpy, never ``bool``) in an interval; returns ``int``."""

    def describe(self) -> str:
        return f"an integer in {self._range()}"

    def coerce(self, name: str, value: Any) -> int:
        if not _is_int(value) or not self._inside(int(value)):
            raise invalid(name, value, self.describe(), self.why)
        return int(value)


@dataclass(frozen=True)
class Real(_Interval):
    """A finite real number (int or float, never ``bool``) in an interval; returns ``float``."""

    def describe(self) -> str:
        return f"a number in {self._range()}"

    def coerce(self, name: str, value: Any) -> float:
        if not _is_real(value) or not math.isfinite(float(value)) or not self._inside(float(value)):
            raise invalid(name, value, self.describe(), self.why)
        return float(value)


@dataclass(frozen=True)
class Boolean(Constraint):
    """``True`` or ``False`` (numpy booleans accepted); returns ``bool``."""

    why: str | None = None

    def describe(self) -> str:
        return "True or False"

    def coerce(self, name: str, value: Any) -> bool:
        if not isinstance(value, bool | np.bool_):
            raise invalid(name, value, self.describe(), self.why)
        return bool(value)


class Options(Constraint):
    """One of a fixed set of values; with a ``StrEnum`` class, returns the enum member."""

    def __init__(self, values: Iterable[Any] | type[Enum], *, why: str | None = None) -> None:
        self.enum = values if isinstance(values, type) and issubclass(values, Enum) else None
        self.values = tuple(m.value for m in values) if self.enum else tuple(values)
        self.why = why

    def describe(self) -> str:
        return f"one of {list(self.values)}"

    def coerce(self, name: str, value: Any) -> Any:
        try:
            ok = value in self.values
        except TypeError:  # unhashable or incomparable
            ok = False
        if not ok or isinstance(value, bool):
            raise invalid(name, value, self.describe(), self.why)
        return self.enum(value) if self.enum else value


class IntegerSequence(Constraint):
    """A non-empty sequence (not a string) of distinct integers in an interval; returns a tuple."""

    def __init__(
        self,
        low: int = 0,
        high: float = math.inf,
        *,
        unique: bool = True,
        min_length: int = 1,
        why: str | None = None,
    ) -> None:
        self.item = Integer(low, high)
        self.unique = unique
        self.min_length = min_length
        self.why = why

    def describe(self) -> str:
        what = "distinct integers" if self.unique else "integers"
        size = "a non-empty" if self.min_length == 1 else f"at least {self.min_length}"
        return f"{size} sequence of {what} in {self.item._range()}"

    def coerce(self, name: str, value: Any) -> tuple[int, ...]:
        if (
            isinstance(value, str | bytes)
            or not isinstance(value, Sequence | np.ndarray | range)
            or len(value) < self.min_length
        ):
            raise invalid(name, value, self.describe(), self.why)
        out = []
        for v in value:
            if not _is_int(v) or not self.item._inside(int(v)):
                raise invalid(name, value, self.describe(), f"{v!r} is not")
            out.append(int(v))
        if self.unique and len(set(out)) != len(out):
            dup = sorted({v for v in out if out.count(v) > 1})
            raise invalid(name, value, self.describe(), f"{dup} repeat")
        return tuple(out)


class RealSequence(Constraint):
    """A non-empty sequence (not a string) of distinct finite reals in an interval; returns a tuple."""

    def __init__(
        self, low: float, high: float, *, closed: str = "both", why: str | None = None
    ) -> None:
        self.item = Real(low, high, closed=closed)
        self.why = why

    def describe(self) -> str:
        return f"a non-empty sequence of distinct numbers in {self.item._range()}"

    def coerce(self, name: str, value: Any) -> tuple[float, ...]:
        if isinstance(value, str | bytes) or not isinstance(value, Sequence | np.ndarray):
            raise invalid(name, value, self.describe(), self.why)
        if len(value) == 0:
            raise invalid(name, value, self.describe(), self.why)
        out = []
        for v in value:
            if not _is_real(v) or not math.isfinite(float(v)) or not self.item._inside(float(v)):
                raise invalid(name, value, self.describe(), f"{v!r} is not")
            out.append(float(v))
        if len(set(out)) != len(out):
            dup = sorted({v for v in out if out.count(v) > 1})
            raise invalid(name, value, self.describe(), f"{dup} repeat")
        return tuple(out)


class OptionSequence(Constraint):
    """A non-empty sequence (not a string) of distinct values from a fixed set; returns a tuple."""

    def __init__(self, values: Iterable[Any], *, why: str | None = None) -> None:
        self.values = tuple(values)
        self.why = why

    def describe(self) -> str:
        return f"a non-empty sequence of distinct values from {list(self.values)}"

    def coerce(self, name: str, value: Any) -> tuple[Any, ...]:
        if isinstance(value, str | bytes) or not isinstance(value, Sequence) or not value:
            raise invalid(name, value, self.describe(), self.why)
        for v in value:
            if v not in self.values:
                raise invalid(name, value, self.describe(), f"{v!r} is not")
        if len(set(value)) != len(value):
            dup = sorted({v for v in value if list(value).count(v) > 1})
            raise invalid(name, value, self.describe(), f"{dup} repeat")
        return tuple(value)


def check(name: str, value: Any, *constraints: Constraint | None) -> Any:
    """Validate ``value`` against the constraints (any may hold; ``None`` allows ``None``).

    Returns the value coerced by the first constraint it satisfies. On failure the message names
    the value and every allowed form.
    """
    if value is None and None in constraints:
        return None
    real = [c for c in constraints if c is not None]
    errors = []
    for c in real:
        try:
            return c.coerce(name, value)
        except ValueError as e:
            errors.append(e)
    if len(real) == 1 and None not in constraints:
        raise errors[0]
    forms = [c.describe() for c in real] + (["None"] if None in constraints else [])
    whys = "; ".join(c.why for c in real if c.why)
    raise invalid(name, value, " or ".join(forms), whys or None)


def check_params(params: dict[str, Any], constraints: dict[str, Any]) -> dict[str, Any]:
    """Validate every entry of ``params`` that has a constraint (a constraint or a tuple of them).

    Returns a new dict with the coerced values; parameters without a constraint pass unchanged.
    """
    out = dict(params)
    for name, cons in constraints.items():
        if name in out:
            cons = cons if isinstance(cons, tuple) else (cons,)
            out[name] = check(name, out[name], *cons)
    return out


def from_fields(cls: type, value: Mapping[str, Any], what: str) -> Any:
    """``cls(**value)`` for a dataclass ``cls``, refusing keys that are not its fields by name
    (``what`` names the options in the message).

    >>> from dataclasses import dataclass
    >>> @dataclass
    ... class Opts:
    ...     a: int = 1
    >>> from_fields(Opts, {"a": 2}, "demo")
    Opts(a=2)
    >>> from_fields(Opts, {"b": 2}, "demo")
    Traceback (most recent call last):
    ...
    ValueError: Unknown demo option(s) ['b']. Allowed: ['a']
    """
    allowed = [f.name for f in dataclasses.fields(cls)]
    if not isinstance(value, Mapping):  # a string would be read as its characters
        raise invalid(what, value, f"a mapping of {cls.__name__}'s fields {allowed}")
    unknown = sorted(set(value) - set(allowed))
    if unknown:
        raise ValueError(f"Unknown {what} option(s) {unknown}. Allowed: {allowed}")
    return cls(**value)
