"""Registry of diagnosers: ``make(name, **hyperparameters)``, ``available()``, ``diagnoser_class``.

Diagnosers outside this package join the registry in one of three ways:

* a module that defines them with ``@diagnosers.register("name")`` is imported (by the user's
  code, or by ``python -m evaluation.leaderboard --import MODULE``: :func:`import_modules`);
* an installed distribution declares an entry point in the group
  ``fcc_fault_diagnosis.diagnosers`` (:data:`ENTRY_POINT_GROUP`), for example in its
  ``pyproject.toml``::

      [project.entry-points."fcc_fault_diagnosis.diagnosers"]
      my-det = "my_package.detectors"            # a module that registers on import
      other-det = "my_package.detectors:Other"   # or a Diagnoser subclass, registered as other-det

  Entry points are loaded lazily, the first time :func:`available` is called or a name is not
  found, in the driver and in every worker process alike.

>>> diagnoser_class("limits").fast_params()
{}
"""

from __future__ import annotations

import importlib
import logging
import warnings
from collections.abc import Callable, Iterable
from importlib import metadata
from typing import Any

from diagnosers.contract import DiagnoserContract

logger = logging.getLogger(__name__)

#: Entry-point group of third-party diagnosers (see the module docstring).
ENTRY_POINT_GROUP = "fcc_fault_diagnosis.diagnosers"

_REGISTRY: dict[str, type[DiagnoserContract]] = {}
_ENTRY_POINTS_LOADED = False


def register(name: str) -> Callable[[type[DiagnoserContract]], type[DiagnoserContract]]:
    """Class decorator: make ``cls`` available as ``diagnosers.make(name)``."""

    def deco(cls: type[DiagnoserContract]) -> type[DiagnoserContract]:
        if not (isinstance(cls, type) and issubclass(cls, DiagnoserContract)):
            raise ValueError(
                f"register({name!r}) was given {cls!r}, which is not a diagnoser; register a "
                "subclass of diagnosers.Diagnoser (or of diagnosers.contract.DiagnoserContract)"
            )
        if name in _REGISTRY and _REGISTRY[name] is not cls:
            # A module imported twice under two names (``python script.py`` runs it as
            # __main__) defines a second class of the same qualified name: say so.
            raise ValueError(
                f"diagnoser name {name!r} is already registered to {_REGISTRY[name]}; "
                f"cannot register {cls} too (choose another name, or import the module once)"
            )
        cls.name = name
        _REGISTRY[name] = cls
        return cls

    return deco


def unregister(name: str) -> None:
    """Remove ``name`` from the registry (a no-op for an unknown name).

    For code that registers a diagnoser for a while, e.g. a test of a deliberately broken one.
    """
    cls = _REGISTRY.pop(name, None)
    if cls is not None and cls.name == name:
        cls.name = ""


def import_modules(modules: Iterable[str]) -> None:
    """Import ``modules`` (dotted names) so that the diagnosers they register become available.

    A module is imported, never run as a script, so it needs no ``if __name__ == "__main__"``
    guard. Raises ``ValueError`` naming a module that cannot be imported, with the reason.
    """
    for mod in modules:
        if not isinstance(mod, str) or not mod.strip() or mod.strip().startswith("."):
            raise ValueError(
                f"module={mod!r} is outside the allowed range: an absolute dotted module name "
                "(not relative), e.g. examples.cusum_diagnoser"
            )
        try:
            importlib.import_module(mod.strip())
        except Exception as e:  # the user's module may raise anything while it is imported
            raise ValueError(
                f"cannot import module {mod!r} ({type(e).__name__}: {_one_line(e)}); give a "
                "dotted module name importable from the current directory or the installed "
                "packages that defines (or registers) only diagnosers, e.g. "
                "examples.cusum_diagnoser"
            ) from e


def _one_line(e: BaseException) -> str:
    if isinstance(e, SyntaxError):
        return f"{e.msg} at {e.filename}, line {e.lineno}"
    return " ".join(str(e).split())


def load_entry_points(*, force: bool = False) -> None:
    """Load the diagnosers of :data:`ENTRY_POINT_GROUP` (once per process unless ``force``).

    An entry point that fails to load, or whose name is already registered (a built-in
    diagnoser's), is skipped with a ``RuntimeWarning`` naming both, so one broken plug-in does
    not hide the others nor replace a built-in diagnoser.
    """
    global _ENTRY_POINTS_LOADED
    if _ENTRY_POINTS_LOADED and not force:
        return
    _ENTRY_POINTS_LOADED = True
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        try:
            obj = ep.load()
        except Exception as e:  # a third-party module may raise anything on import
            warnings.warn(
                f"diagnoser entry point {ep.name!r} = {ep.value!r} failed to load "
                f"({type(e).__name__}: {e}); skipped",
                RuntimeWarning,
                stacklevel=2,
            )
            continue
        # a class its module registered itself (its own ``name``, not one it inherits) is known
        own = obj.__dict__.get("name", "") if isinstance(obj, type) else ""
        if (
            isinstance(obj, type)
            and issubclass(obj, DiagnoserContract)
            and not (own and _REGISTRY.get(own) is obj)
        ):
            if _REGISTRY.get(ep.name, obj) is not obj:
                # a plug-in never replaces a diagnoser already known (a built-in one): a clash
                # warns, and the plug-ins after it still load
                warnings.warn(
                    f"diagnoser entry point {ep.name!r} = {ep.value!r} ({obj}) has the name of "
                    f"{_REGISTRY[ep.name]}, which is kept; the plug-in is skipped (rename its "
                    "entry point)",
                    RuntimeWarning,
                    stacklevel=2,
                )
                continue
            register(ep.name)(obj)
        logger.debug("loaded diagnoser entry point %s = %s", ep.name, ep.value)


def available() -> list[str]:
    """Names accepted by :func:`make`, sorted (entry-point plug-ins included)."""
    load_entry_points()
    return sorted(_REGISTRY)


def diagnoser_class(name: str) -> type[DiagnoserContract]:
    """The class registered as ``name`` (e.g. to read its ``fast_params()``)."""
    if name not in _REGISTRY:
        load_entry_points()
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ValueError(
            f"Unknown diagnoser {name!r}. Available: {available()}. A diagnoser of your own "
            "must be registered first: import its module (leaderboard: --import MODULE) or "
            f"install a package with a {ENTRY_POINT_GROUP!r} entry point"
        ) from None


def make(name: str, **hyperparameters: Any) -> DiagnoserContract:
    """Build the diagnoser registered as ``name`` with the given hyperparameters."""
    cls = diagnoser_class(name)
    cls.check_param_names(hyperparameters)
    return cls(**hyperparameters)
