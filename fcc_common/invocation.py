"""The parser of every command line: its name as the user typed it, and examples in its help.

``python -m pkg`` sets ``sys.argv[0]`` to the module's file (``__main__.py``, ``demo.py``), which
argparse would print as the program's name although nobody can type it back; a console script
(``fcc-leaderboard``) sets it to the script's name, which argparse prints as it is.
"""

from __future__ import annotations

import argparse
import errno
import os
import shutil
import sys
import textwrap
import warnings
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import NoReturn

__all__ = [
    "INPUT_ERRORS",
    "check_out_path",
    "command_parser",
    "csv_list",
    "import_from_cwd",
    "interrupted",
    "os_error_text",
    "out_path",
    "prog_name",
    "refuse",
    "run_command",
    "user_modules",
]

#: What a command refuses in one line with exit code 2, as argparse refuses a bad argument: a
#: value out of range, a path that cannot be read or written, a module that cannot be imported.
#: Any other exception is a bug of ours and keeps its traceback.
INPUT_ERRORS: tuple[type[BaseException], ...] = (ValueError, OSError, ImportError, SyntaxError)


def prog_name(module: str) -> str:
    """The command as it was invoked: the console script's name, else ``python -m module``.

    Args:
        module: the dotted module the command runs as with ``python -m`` (for a package, the
            package, not its ``__main__``).
    """
    name = os.path.basename(sys.argv[0]) if sys.argv else ""
    # "-c", an empty argv[0] (embedded) and any .py file are not names a user can re-run
    if not name or name == "-c" or name.endswith(".py"):
        return f"python -m {module}"
    return name


def command_parser(
    module: str, description: str, examples: Sequence[tuple[str, str]]
) -> argparse.ArgumentParser:
    """An :class:`argparse.ArgumentParser` named by :func:`prog_name`, with examples as epilog.

    Args:
        module: see :func:`prog_name`.
        description: paragraphs separated by blank lines, wrapped to the terminal here (the
            formatter prints text as written, so that the examples keep their layout).
        examples: ``(arguments, what it does)`` pairs, printed after the prog as typed.
    """
    if not examples:
        raise ValueError(f"command_parser({module!r}): give at least one example, got none")
    prog = prog_name(module)
    width = max(40, min(100, shutil.get_terminal_size().columns - 2))  # argparse's own width
    paragraphs = (" ".join(p.split()) for p in description.strip().split("\n\n"))
    lines = ["examples:"]
    for args, what in examples:
        lines.append(f"  {prog} {args}".rstrip())
        lines += textwrap.wrap(what, width, initial_indent=" " * 6, subsequent_indent=" " * 6)
    return argparse.ArgumentParser(
        prog=prog,
        description="\n\n".join(textwrap.fill(p, width) for p in paragraphs),
        epilog="\n".join(lines),
        formatter_class=argparse.RawDescriptionHelpFormatter,
        # no prefix matching: "--seed 1" must not be read as "--seeds 1", nor a typo as a flag
        allow_abbrev=False,
    )


def os_error_text(e: OSError) -> str:
    """One line for a failed read or write: the path, the reason, and what a path must be."""
    where = " -> ".join(repr(str(f)) for f in (e.filename, e.filename2) if f is not None)
    reason = e.strerror or type(e).__name__
    if not where:
        return f"{reason}: {e}"
    return (
        f"cannot use {where}: {reason}; give a path whose parent is a writable directory "
        "(readable, for an input)"
    )


def refuse(parser: argparse.ArgumentParser, e: BaseException) -> NoReturn:
    """Exit like argparse (code 2, usage line, one message line) for one of :data:`INPUT_ERRORS`."""
    text = os_error_text(e) if isinstance(e, OSError) else str(e)
    if isinstance(e, SyntaxError):
        text = f"syntax error in {e.filename}, line {e.lineno}: {e.msg}"
    parser.error(" ".join(text.split()) or type(e).__name__)


def run_command(
    parser: argparse.ArgumentParser,
    body: Callable[[argparse.Namespace], int | None],
    argv: Sequence[str] | None,
    *,
    on_interrupt: str = "re-run the command to start again",
) -> int:
    """Parse ``argv`` and run ``body(args)``; any of :data:`INPUT_ERRORS` becomes one line, and
    so does a Ctrl-C (followed by ``on_interrupt``, what re-running does).

    The one place where every command turns a bad value or an unusable path, found however late,
    into ``prog: error: ...`` and exit code 2 instead of a traceback; and an interruption into
    ``prog: interrupted ...`` and exit code 130 (128 + SIGINT, the shell's convention). Every
    file the commands write is written whole (:func:`fcc_common.io.atomic_write`), so an
    interrupted command leaves no torn file. ``body`` returning ``None`` exits with 0.
    """
    args = parser.parse_args(argv)
    shown = warnings.formatwarning
    # a warning is one line too: the command's name and the message, not our source line
    warnings.formatwarning = lambda message, *_a, **_k: f"{parser.prog}: warning: {message}\n"
    try:
        code = body(args)
    except INPUT_ERRORS as e:
        refuse(parser, e)
    except KeyboardInterrupt:
        interrupted(parser, on_interrupt)
    finally:
        warnings.formatwarning = shown
    return 0 if code is None else code


def interrupted(parser: argparse.ArgumentParser, then: str) -> NoReturn:
    """Exit after a Ctrl-C with one line and code 130, without a traceback; ``then`` says what
    re-running does."""
    parser.exit(
        130, f"{parser.prog}: interrupted (Ctrl-C); files written so far are whole: {then}\n"
    )


def out_path(text: str) -> Path:
    """An argparse ``type`` for an output path: refuses an empty one, which ``Path("")`` would
    silently turn into the current directory."""
    if not text.strip():
        raise argparse.ArgumentTypeError(
            f"{text!r} is empty; give a directory path (use '.' for the current directory)"
        )
    return Path(text)


def check_out_path(flag: str, out: str | os.PathLike) -> Path:
    """Refuse an output path that is empty, is or lies under a regular file, or whose nearest
    existing folder is not writable; before any work, so that a long run cannot fail at its end.

    Returns the path. Raises ``ValueError`` naming ``flag``, the value and why.
    """
    text = os.fspath(out)
    if not str(text).strip():
        raise ValueError(
            f"{flag} {text!r} is empty; give a directory or file path (use '.' for the current "
            "directory)"
        )
    path = Path(text)
    for p in (path, *path.parents):
        if not p.exists():
            continue
        if p != path and not p.is_dir():
            raise ValueError(
                f"{flag} {str(path)!r} lies under {str(p)!r}, which is a regular file, not a "
                "directory; choose another output path"
            )
        folder = p if p.is_dir() else p.parent
        if not os.access(folder, os.W_OK | os.X_OK):
            raise ValueError(
                f"{flag} {str(path)!r}: {str(folder)!r} is not writable "
                f"({os.strerror(errno.EACCES)}); choose a writable location"
            )
        break
    return path


def csv_list(text: str) -> tuple[str, ...]:
    """An argparse ``type``: a non-empty comma-separated list of names, stripped."""
    items = tuple(t.strip() for t in text.split(",") if t.strip())
    if not items:
        raise argparse.ArgumentTypeError(f"expected a comma-separated list, got {text!r}")
    return items


def import_from_cwd(modules: Sequence[str], importer: Callable[[Iterable[str]], None]) -> None:
    """``importer(modules)`` (e.g. :func:`diagnosers.registry.import_modules`) finding modules as
    ``python -m`` would: the current directory first (a console script does not put it on
    ``sys.path``; local workers inherit the path)."""
    if not modules:
        return
    cwd = os.getcwd()
    if cwd not in sys.path and "" not in sys.path:
        sys.path.insert(0, cwd)
    importer(modules)


def user_modules(groups: Iterable[Iterable[str]]) -> tuple[str, ...]:
    """The modules of a repeatable ``--import`` option (a list of :func:`csv_list` values),
    flattened, in order, without repeats."""
    return tuple(dict.fromkeys(m for group in groups for m in group))
