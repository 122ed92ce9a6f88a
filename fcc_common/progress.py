"""Progress bars of the long commands: tqdm on standard error, only when interactive or asked.

A command's ``--progress`` / ``--no-progress`` (:func:`add_progress_flag`) asks for a bar or
refuses one; without either, a bar is drawn only when standard error is a terminal and this is
the main process (:func:`auto_progress`). Bars write to standard error only, so a command's
output on standard output and its files are the same with and without them.
"""

from __future__ import annotations

import argparse
import multiprocessing
import sys
from collections.abc import Iterable
from typing import Any

__all__ = ["add_progress_flag", "auto_progress", "progress_bar"]


def auto_progress(progress: bool | None) -> bool:
    """Resolve a ``progress`` option: ``None`` means "auto", a bar only when run interactively.

    Interactive: standard error is a terminal and this is the main process (a sweep's worker
    processes share the terminal, and their bars would garble the sweep's own).

    >>> auto_progress(True), auto_progress(False)
    (True, False)
    """
    if progress is not None:
        return bool(progress)
    isatty = getattr(sys.stderr, "isatty", None)
    interactive = bool(isatty and isatty())
    return interactive and multiprocessing.parent_process() is None


def progress_bar(
    iterable: Iterable[Any] | None = None,
    *,
    total: float | None = None,
    desc: str,
    unit: str,
    progress: bool | None,
) -> Any:
    """A tqdm bar on standard error, drawn when :func:`auto_progress` says so (disabled, it
    costs nothing and prints nothing); it leaves no line behind when it closes."""
    from tqdm.auto import tqdm

    return tqdm(
        iterable,
        total=total,
        desc=desc,
        unit=unit,
        disable=not auto_progress(progress),
        leave=False,
        file=sys.stderr,
        dynamic_ncols=True,
    )


def add_progress_flag(parser: argparse.ArgumentParser) -> None:
    """``--progress`` / ``--no-progress`` on ``parser`` (``args.progress``: True, False, or
    None for "only when standard error is a terminal")."""
    parser.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="progress bars on standard error (default: only when it is a terminal); "
        "--no-progress: none. The results are the same either way",
    )
