"""Evaluation of diagnosers, one sub-package per job:

================  ================================================================================
``metrics``       pure scores: detection and isolation indexes, bootstrap intervals
``sweep``         running a sweep: diagnosers × episodes, in parallel, over a resumable store
``tracks``        the benchmark: tracks, their reference rows and goals, the per-track tables
``isolation``     fault isolation studies (isolability, unknown faults)
``reports``       tables, figures and the files a run writes
``leaderboard``   ``python -m evaluation.leaderboard``: the command line
``discover``      ``python -m evaluation.discover``: close the modelling loop on measured data
``control``       ``python -m evaluation.control``: the control task's study (what a policy earns)
================  ================================================================================

Kept free of heavy imports so that ``import evaluation.metrics`` stays cheap: ``__version__``
(the one version of the project, :data:`fcc_env.__version__`) is read on first access.
"""

from typing import Any


def __getattr__(name: str) -> Any:
    if name == "__version__":
        from fcc_env import __version__

        return __version__
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
