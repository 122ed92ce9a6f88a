"""The leaderboard: ``python -m evaluation.leaderboard [--quick] [--track NAME] [...]``.

==============  ==================================================================================
``command``     :func:`main`: the command line (see its module for the files written)
``arguments``   the parser and the checks both modes share
``paper``       the paper leaderboard as a library: :class:`LeaderboardOptions`, :func:`run`
``track_runs``  ``--track``: the benchmark tracks of :mod:`evaluation.tracks`
==============  ==================================================================================
"""

from evaluation.leaderboard.command import main

__all__ = ["main"]
