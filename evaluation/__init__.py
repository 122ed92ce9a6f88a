"""Evaluation of diagnosers: pure metrics (:mod:`evaluation.metrics`), harness, leaderboard, plots.

Kept free of heavy imports so that ``import evaluation.metrics`` stays cheap: ``__version__``
(the one version of the project, :data:`fcc_env.__version__`) is read on first access.
"""

from typing import Any


def __getattr__(name: str) -> Any:
    if name == "__version__":
        from fcc_env import __version__

        return __version__
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
