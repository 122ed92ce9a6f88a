"""Pluggable fault-diagnosis agents that watch FCC episodes.

The rooms (the contract, the registry and the presets at the top; the parts below):

=====================  ===========================================================================
``contract``           :class:`~diagnosers.contract.DiagnoserContract`: ``fit`` / ``reset`` /
                       ``update`` / ``detect``, parameters, validation
``diagnoser``          :class:`Diagnoser`: the contract plus saving and loading without pickles
``detection``          :class:`Decision` (one sample) and :class:`Detection` (an episode)
``registry``           :func:`make`, :func:`available`, :func:`register`, ``--import`` modules
``presets``            hyperparameters declared once; registered variants that differ in defaults
``range_guard``        ``<name>-novelty`` variants: a detector's alarms plus the samples outside
                       its training set-point range, flagged novel (:func:`novelty_variant`)
``conformance``        :func:`check_diagnoser`: the contract as a public test suite
``tuning/``            tuning on labelled episodes: :func:`grid_search`, :func:`make_scorer` for
                       scikit-learn's ``GridSearchCV``
``episode/``           :class:`Episode`, the input, with its checks and units
``classical/``         the baselines: ``limits``, ``pca``, ``arx-band``
``networks/``          the LRGF network, the NNARX model-error model and their training
``bank/``              a bank of relations: their models, parallel training and cache
``stages/``            alarm stages: filters, statistics, limits, the paper's band
``lrgf/``              the LRGF detectors (``lrgf-mem``, ``lrgf-glr`` and their presets)
``isolation/``         the isolators ``lrgf-iso``, ``lrgf-lda`` and ``mmae``
``filters/``           state estimators of the FCC model: the unscented Kalman filter's
                       innovations, state and disturbance estimates, and the grey-box
                       detector ``ukf-glr`` on them
``loops/``             control-loop monitors on a loop's own records: ``oscillation-acf``,
                       ``stiction-ccf``, ``valve-glr``, ``loop-offset``, ``air-deficit``
``sensors/``           sensor validation by analytical redundancy: ``sensor-validation``
=====================  ===========================================================================

>>> import diagnosers
>>> "limits" in diagnosers.available()
True
"""

from diagnosers.conformance import ConformanceError, check_diagnoser
from diagnosers.contract import NotFittedError, Tier
from diagnosers.detection import SCORE_THRESHOLD, UNKNOWN, Decision, Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode import Episode
from diagnosers.registry import available, diagnoser_class, import_modules, make, register
from diagnosers.tuning.grid_search import grid_search  # scikit-learn is imported when it runs
from diagnosers.tuning.scorer import episode_labels, make_scorer
from fcc_env import __version__  # the project's one version

# isort: split
# Importing the model modules registers their diagnosers (after the registry exists).
from diagnosers import (
    classical,  # noqa: F401  (registers limits, pca, arx-band)
    filters,  # noqa: F401  (registers ukf-glr)
    isolation,  # noqa: F401  (registers lrgf-iso, lrgf-lda, mmae)
    loops,  # noqa: F401  (registers oscillation-acf, stiction-ccf, valve-glr)
    lrgf,  # noqa: F401  (registers lrgf-mem, lrgf-glr and their presets)
    sensors,  # noqa: F401  (registers sensor-validation)
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
    "Tier",
    "__version__",
    "available",
    "check_diagnoser",
    "diagnoser_class",
    "episode_labels",
    "grid_search",
    "import_modules",
    "make",
    "make_scorer",
    "register",
]
