"""The modules a module depends on, read from its source: the closure of its imports.

Used to name what a stored result depends on (the reference rows' ``REFERENCE_CODE``), so that a
new dependency cannot be left off a hand-written list: a module that a listed module imports is
listed too. The graph is read from the source files (:mod:`ast`), not by importing them, and
every ``import`` statement counts, also one inside a function or under ``TYPE_CHECKING``: a
dependency counted that is not one recomputes a stored result, while one missed would let a
stale result be read.

What the source does not say is not seen: a module imported by name at run time
(``importlib.import_module(name)``, a registry lookup such as ``diagnoser_class("lrgf-glr")``)
must be given as a root by whoever knows it.
"""

from __future__ import annotations

import ast
import importlib.util
from collections.abc import Iterable
from functools import cache
from pathlib import Path

__all__ = ["import_closure", "module_file"]


@cache
def module_file(name: str) -> Path | None:
    """The source file of module ``name`` (a package: its ``__init__.py``), or ``None`` when
    ``name`` is not an importable module (an attribute imported from a module, say)."""
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):  # a parent that is a module, not a package
        return None
    if spec is None or spec.origin is None or not spec.origin.endswith(".py"):
        return None
    return Path(spec.origin)


def _imports(name: str, path: Path) -> set[str]:
    """The modules that module ``name`` (source ``path``) imports, by absolute name."""
    tree = ast.parse(path.read_bytes(), filename=str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # a relative import: from the package, level-1 levels up
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*parts, base] if base else parts)
            for alias in node.names:
                sub = f"{base}.{alias.name}"  # ``from pkg import module`` imports the module
                found.add(sub if module_file(sub) is not None else base)
    return found


def import_closure(
    roots: Iterable[str], packages: Iterable[str], exclude: Iterable[str] = ()
) -> tuple[str, ...]:
    """Every module of ``packages`` that the modules ``roots`` import, directly or through
    another such module, the roots included; sorted.

    Args:
        roots: module names to start from (each must be a module of ``packages``).
        packages: top-level package names the closure is kept to (the project's own);
            imports of other packages (numpy, the standard library) are not followed.
        exclude: modules (or whole packages: a prefix before a dot) left out and not
            followed, e.g. a package whose results are named by a version of their own.

    Raises:
        ValueError: a root that is not a module of ``packages``, or that has no source file.
    """
    packages, exclude = tuple(packages), tuple(exclude)

    def kept(m: str) -> bool:
        top_ok = m.split(".")[0] in packages
        return top_ok and not any(m == x or m.startswith(x + ".") for x in exclude)

    todo = list(roots)
    for r in todo:
        if not kept(r) or module_file(r) is None:
            raise ValueError(
                f"root {r!r} is not a module with a source file of the packages {packages} "
                f"(excluded: {exclude}); allowed: such a module's dotted name"
            )
    seen: set[str] = set()
    while todo:
        m = todo.pop()
        if m in seen:
            continue
        seen.add(m)
        path = module_file(m)
        if path is None:  # pragma: no cover - only kept, importable names are queued
            continue
        todo.extend(d for d in _imports(m, path) if kept(d) and d not in seen)
    return tuple(sorted(m for m in seen if module_file(m) is not None))
