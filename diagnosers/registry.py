"""Registry of diagnosers: ``make(name, **hyperparameters)``, ``available()``, ``diagnoser_class``.

>>> diagnoser_class("limits").fast_params()
{}
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from diagnosers.base import Diagnoser

_REGISTRY: dict[str, type[Diagnoser]] = {}


def register(name: str) -> Callable[[type[Diagnoser]], type[Diagnoser]]:
    """Class decorator: make ``cls`` available as ``diagnosers.make(name)``."""

    def deco(cls: type[Diagnoser]) -> type[Diagnoser]:
        if name in _REGISTRY and _REGISTRY[name] is not cls:
            raise ValueError(f"diagnoser name {name!r} is already registered to {_REGISTRY[name]}")
        cls.name = name
        _REGISTRY[name] = cls
        return cls

    return deco


def available() -> list[str]:
    """Names accepted by :func:`make`, sorted."""
    return sorted(_REGISTRY)


def diagnoser_class(name: str) -> type[Diagnoser]:
    """The class registered as ``name`` (e.g. to read its :meth:`Diagnoser.fast_params`)."""
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ValueError(f"Unknown diagnoser {name!r}. Available: {available()}") from None


def make(name: str, **hyperparameters: Any) -> Diagnoser:
    """Build the diagnoser registered as ``name`` with the given hyperparameters."""
    cls = diagnoser_class(name)
    allowed = cls._param_names()
    unknown = sorted(set(hyperparameters) - set(allowed))
    if unknown:
        raise ValueError(
            f"Unknown hyperparameter(s) {unknown} for diagnoser {name!r}. Allowed: {allowed}"
        )
    return cls(**hyperparameters)
