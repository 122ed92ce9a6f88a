"""The parser of every command line: its name as the user typed it, and examples in its help.

``python -m pkg`` sets ``sys.argv[0]`` to the module's file (``__main__.py``, ``demo.py``), which
argparse would print as the program's name although nobody can type it back; a console script
(``fcc-leaderboard``) sets it to the script's name, which argparse prints as it is.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import textwrap
from collections.abc import Sequence

__all__ = ["command_parser", "prog_name"]


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
    )
