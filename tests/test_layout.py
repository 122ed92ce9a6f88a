"""The package layout's rules, checked on the source (issues 30, 41): rooms stay small and one-way.

* no module over :data:`MAX_MODULE_LINES` code lines and no class over :data:`MAX_CLASS_LINES`
  (code lines: docstrings, comments and blank lines are free, so a cap never argues against
  explaining; a room near its cap is split by job, not packed with ``# fmt: skip``);
* no private name (``_x``) imported from another module;
* no module basename twice across the packages (a file name is a job);
* no import cycle between modules, counting imports inside functions (a deferred import is
  how a cycle hides);
* no ``# fmt: skip`` in the packages (the formatter lays every line out);
* every module and sub-package appears in its package's room table (the face's docstring), and
  every row of a table names one.
"""

from __future__ import annotations

import ast
import io
import tokenize
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("fcc_common", "fcc_env", "diagnosers", "evaluation")
MAX_MODULE_LINES = 500
MAX_CLASS_LINES = 300


def _modules() -> list[Path]:
    return sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py"))


def _tree(path: Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


def _rel(path: Path) -> str:
    return str(path.relative_to(ROOT))


def _code_lines(path: Path) -> set[int]:
    """The line numbers of a module that hold code: not blank, not only a comment, not part of
    a docstring."""
    text = path.read_text(encoding="utf-8")
    doc_lines: set[int] = set()
    for node in ast.walk(_tree(path)):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                if isinstance(body[0].value.value, str):
                    doc_lines |= set(range(body[0].lineno, body[0].end_lineno + 1))
    code = set()
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type not in (
            tokenize.COMMENT,
            tokenize.NL,
            tokenize.NEWLINE,
            tokenize.INDENT,
            tokenize.DEDENT,
            tokenize.ENDMARKER,
        ):
            code |= set(range(tok.start[0], tok.end[0] + 1))
    return code - doc_lines


def test_code_lines_skip_docstrings_and_comments(tmp_path: Path) -> None:
    src = tmp_path / "m.py"
    src.write_text(
        '"""Doc\n\nmore."""\n\n# a comment\nx = 1  # why\n\n\ndef f():\n    """Doc."""\n    return x\n'
    )
    assert sorted(_code_lines(src)) == [6, 9, 11]


def test_the_packages_exist() -> None:
    # guards the checks below against passing on an empty tree
    assert len(_modules()) > 50


def test_no_module_over_the_line_limit() -> None:
    long = {_rel(p): n for p in _modules() if (n := len(_code_lines(p))) > MAX_MODULE_LINES}
    assert not long, f"modules over {MAX_MODULE_LINES} lines: {long}"


def test_no_class_over_the_line_limit() -> None:
    big = {}
    for p in _modules():
        code = _code_lines(p)
        for node in ast.walk(_tree(p)):
            if isinstance(node, ast.ClassDef):
                n = len(code & set(range(node.lineno, node.end_lineno + 1)))
                if n > MAX_CLASS_LINES:
                    big[f"{_rel(p)}:{node.name}"] = n
    assert not big, f"classes over {MAX_CLASS_LINES} lines: {big}"


def test_no_private_name_imported_across_modules() -> None:
    crossing = []
    for p in _modules():
        for node in ast.walk(_tree(p)):
            if isinstance(node, ast.ImportFrom) and node.module:
                for alias in node.names:
                    if alias.name.startswith("_") and not alias.name.startswith("__"):
                        crossing.append(f"{_rel(p)}: from {node.module} import {alias.name}")
    assert not crossing, "private names imported across modules:\n" + "\n".join(crossing)


def test_no_module_name_twice() -> None:
    names = Counter(p.stem for p in _modules() if p.stem not in {"__init__", "__main__"})
    twice = sorted(n for n, c in names.items() if c > 1)
    assert not twice, f"module names used more than once: {twice}"


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _import_graph() -> dict[str, set[str]]:
    """Module -> the project modules it imports, at the top or inside a function alike.

    A package's ``__init__`` is left out of the graph: it gathers its modules' names, and a
    module importing its own package is a convenience, not a dependency between two jobs.
    """
    paths = {_module_name(p): p for p in _modules() if p.name != "__init__.py"}
    graph: dict[str, set[str]] = {}
    for name, p in paths.items():
        edges = set()
        for node in ast.walk(_tree(p)):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets = [f"{node.module}.{a.name}" for a in node.names] + [node.module]
            edges |= {t for t in targets if t in paths and t != name}
        graph[name] = edges
    return graph


def test_no_import_cycle() -> None:
    # A cycle hidden behind a deferred import is still a cycle: two modules that need each
    # other are one job in two files.
    graph = _import_graph()
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def strongconnect(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph[v]:
            if w not in index:
                strongconnect(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            strongconnect(v)
    assert not cycles, f"import cycles: {cycles}"


def _faces() -> list[Path]:
    return sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("__init__.py"))


def _rooms(face: Path) -> list[str]:
    """The modules and sub-packages beside a package's face (``__init__.py``)."""
    folder = face.parent
    mods = [p.stem for p in folder.glob("*.py") if p.stem not in {"__init__", "__main__"}]
    subs = [p.parent.name for p in folder.glob("*/__init__.py")]
    return sorted(mods + subs)


def _mentions(doc: str, package: str, room: str) -> bool:
    return f"``{room}``" in doc or f"``{room}/``" in doc or f"{package}.{room}" in doc


def test_every_room_is_in_its_face_table() -> None:
    # A package's face (its __init__ docstring) is its room table: a module missing from it is
    # a room nobody will find, and a table row naming no module has drifted from the folder.
    missing, stale = [], []
    for face in _faces():
        package = _module_name(face)
        doc = ast.get_docstring(_tree(face)) or ""
        rooms = _rooms(face)
        missing += [f"{package}.{r}" for r in rooms if not _mentions(doc, package, r)]
        for line in doc.splitlines():
            head = line.split()[0] if line[:1] == "`" else ""  # a row starts at column 0
            if head.startswith("``") and head.endswith("``") and head.count("``") == 2:
                name = head.strip("`").rstrip("/")
                if name.isidentifier() and name not in rooms:
                    stale.append(f"{package}: ``{name}``")
    assert not missing, "modules missing from their package's room table:\n" + "\n".join(missing)
    assert not stale, "room-table rows naming no module:\n" + "\n".join(stale)


def test_no_formatter_escape_in_the_library() -> None:
    # ``# fmt: skip`` packed argument lists to keep modules under the line cap (issue 41): the
    # cap counts code lines and a room near it is split by job, so the formatter has its say.
    packed = [
        f"{_rel(p)}:{i}"
        for p in _modules()
        for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
        if line.rstrip().endswith("# fmt: skip")
    ]
    assert not packed, "formatter escapes in the packages:\n" + "\n".join(packed)
