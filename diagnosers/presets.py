"""Hyperparameters declared once, and registered variants that differ only in their defaults.

A detector family declares its hyperparameters in one table (name -> default) and gets its
keyword-only ``__init__`` from :func:`keyword_init`: it stores every value verbatim, as the
estimator contract of :mod:`diagnosers.contract` asks, and carries a real signature for
``get_params``, ``make`` and the documentation. :func:`preset` registers the same class under
another name with other defaults (``lrgf-mem-paper`` is ``lrgf-mem`` with the paper's settings,
``lrgf-glr-adaptive`` is ``lrgf-glr`` with its baseline on): the one way a variant is made.

>>> class Demo:
...     DEFAULTS = {"a": 1, "b": [2]}
...     __init__ = keyword_init(DEFAULTS)
>>> Demo(a=3).a, Demo().b
(3, [2])
"""

from __future__ import annotations

import copy
import inspect
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

from diagnosers.diagnoser import Diagnoser
from diagnosers.registry import register

__all__ = ["keyword_init", "preset"]

D = TypeVar("D", bound=Diagnoser)


def keyword_init(defaults: Mapping[str, Any]) -> Callable[..., None]:
    """A keyword-only ``__init__`` storing each hyperparameter of ``defaults`` verbatim.

    Defaults are copied per instance, so a default list is never shared between instances.
    """
    names = tuple(defaults)
    params = [inspect.Parameter("self", inspect.Parameter.POSITIONAL_OR_KEYWORD)]
    params += [
        inspect.Parameter(n, inspect.Parameter.KEYWORD_ONLY, default=defaults[n]) for n in names
    ]

    def __init__(self: Any, **hyperparameters: Any) -> None:
        unknown = sorted(set(hyperparameters) - set(names))
        if unknown:
            raise TypeError(
                f"{type(self).__name__} got unknown hyperparameter(s) {unknown}; allowed: "
                f"{list(names)}"
            )
        for n in names:
            value = hyperparameters[n] if n in hyperparameters else copy.deepcopy(defaults[n])
            setattr(self, n, value)

    __init__.__signature__ = inspect.Signature(params)  # type: ignore[attr-defined]
    return __init__


def preset(
    name: str,
    family: type[D],
    defaults: Mapping[str, Any],
    doc: str,
    *,
    module: str,
    attributes: Mapping[str, Any] | None = None,
) -> type[D]:
    """Register ``family`` as ``name`` with ``defaults`` replacing some of its defaults.

    The variant is the same class with another signature: same code, same parameters, same
    saved format. Assign the result to a module-level name of ``module`` (the caller's
    ``__name__``) equal to the class name it gets (``name`` in CamelCase, e.g.
    ``LRGFGLRAdaptive``), so that its instances pickle. ``attributes``: class attributes the
    family reads for a default that depends on the preset (``DEFAULT_RELATIONS``).
    """
    base_defaults: dict[str, Any] = family.DEFAULTS  # type: ignore[attr-defined]
    unknown = sorted(set(defaults) - set(base_defaults))
    if unknown:
        raise ValueError(f"preset {name!r}: {unknown} are not hyperparameters of {family}")
    merged = {**base_defaults, **defaults}
    qualname = "".join(
        part.upper() if part in ("lrgf", "mem", "glr", "pca") else part.title()
        for part in name.split("-")
    )
    cls = type(
        qualname,
        (family,),
        {
            "DEFAULTS": merged,
            "__init__": keyword_init(merged),
            "__doc__": _with_parameters(doc, name, family, defaults),
            "__module__": module,
            "__qualname__": qualname,
            **(attributes or {}),
        },
    )
    return register(name)(cls)  # type: ignore[return-value]


def _with_parameters(doc: str, name: str, family: type, defaults: Mapping[str, Any]) -> str:
    """``doc`` followed by the preset's hyperparameters, generated from the family's table so
    that ``help()`` lists every one and no list is kept by hand."""
    changed = ", ".join(f"``{k}={v!r}``" for k, v in defaults.items()) or "none"
    kept = ", ".join(f"``{k}``" for k in family.DEFAULTS if k not in defaults)  # type: ignore[attr-defined]
    text = inspect.cleandoc(doc)
    return (
        f"{text}\n\nHyperparameters: those of :class:`~{family.__module__}.{family.__qualname__}`"
        f" (each documented there, with its range and unit). ``{name}`` changes {changed}; the "
        f"others keep the family's defaults: {kept}."
    )
