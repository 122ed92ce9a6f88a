"""Pluggable fault-diagnosis agents that watch FCC episodes.

>>> import diagnosers
>>> "limits" in diagnosers.available()
True
"""

from diagnosers.base import Decision, Detection, Diagnoser, Episode, NotFittedError
from diagnosers.registry import available, make, register

__all__ = [
    "Decision",
    "Detection",
    "Diagnoser",
    "Episode",
    "NotFittedError",
    "available",
    "make",
    "register",
]
