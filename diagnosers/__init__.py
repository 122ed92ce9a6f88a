"""Pluggable fault-diagnosis agents that watch FCC episodes.

>>> import diagnosers
>>> "limits" in diagnosers.available()
True
"""

from diagnosers.conformance import ConformanceError, check_diagnoser
from diagnosers.contract import NotFittedError
from diagnosers.detection import SCORE_THRESHOLD, UNKNOWN, Decision, Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode import Episode
from diagnosers.registry import available, diagnoser_class, import_modules, make, register
from diagnosers.search import grid_search  # scikit-learn is imported when it runs
from fcc_env import __version__  # the project's one version

# isort: split
# Importing the model modules registers their diagnosers (after the registry exists).
from diagnosers import (
    classical,  # noqa: F401  (registers limits, pca, arx-band)
    isolators,  # noqa: F401  (registers lrgf-iso, lrgf-lda)
    lrgf_glr,  # noqa: F401  (registers lrgf-glr)
    lrgf_mem,  # noqa: F401  (registers lrgf-mem)
    lrgf_presets,  # noqa: F401  (registers lrgf-mem-paper, lrgf-glr-adaptive)
)

__all__ = [
    "SCORE_THRESHOLD",
    "UNKNOWN",
    "ConformanceError",
    "Decision",
    "Detection",
    "Diagnoser",
    "Episode",
    "NotFittedError",
    "__version__",
    "available",
    "check_diagnoser",
    "diagnoser_class",
    "grid_search",
    "import_modules",
    "make",
    "register",
]
