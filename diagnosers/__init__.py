"""Pluggable fault-diagnosis agents that watch FCC episodes.

>>> import diagnosers
>>> "limits" in diagnosers.available()
True
"""

from diagnosers.base import Decision, Detection, Diagnoser, Episode, NotFittedError
from diagnosers.registry import available, diagnoser_class, make, register

# isort: split
# Importing the model modules registers their diagnosers (after the registry exists).
from diagnosers import (
    baselines,  # noqa: F401  (registers limits, pca, arx-band)
    lrgf_glr,  # noqa: F401  (registers lrgf-glr)
    lrgf_mem,  # noqa: F401  (registers lrgf-mem-paper, lrgf-mem)
)

__all__ = [
    "Decision",
    "Detection",
    "Diagnoser",
    "Episode",
    "NotFittedError",
    "available",
    "diagnoser_class",
    "make",
    "register",
]
