"""Close the modelling loop on measured data: residual → missing effect → add it → error before/after.

``python -m evaluation.discover --data PATH.csv --out DIR [--candidates id,id] [--train-fraction 0.6]
[--max-effects 3]`` or, as a library, :func:`discover`, which returns a frozen
:class:`DiscoveryReport` (``report.to_json()`` is the dict that ``DIR/report.json`` holds).

The package, one room per concern:

========================  =========================================================================
``data``                  :func:`load_measured`, :class:`MeasuredData`: only the ``measured`` and
                          ``commanded`` columns of a dataset (truth columns are never parsed)
``base``                  the adapter protocol: :class:`ModelAdapter`, :class:`Candidate`,
                          :class:`ParamInfo`, :class:`FitResult`
``physics_model``         :class:`PhysicsModel` (the compiled FCC model; candidates: the effects
                          of :mod:`fcc_env.effects` and user :class:`PhysicsCandidate`)
``arx``                   :class:`ARXModel` and the :class:`MissingInput` candidates
``lrgf_model``            :class:`~evaluation.discover.lrgf_model.LRGFModel` (imported on demand: torch)
``fitting``               :func:`fit_effects`: bounded simulation-error least squares
``scoring``               :func:`heldout_comparison`, :func:`structure_statistics`
``loop``                  :func:`discover`
``report``                :class:`DiscoveryReport`, residual tests and plots of the report
``residual_tests``        whiteness, bias, drift and correlation tests of a residual
``cli``                   ``python -m evaluation.discover`` (its wall time: ``python -m bench.loop_speed``)
========================  =========================================================================

Limitations (stated, not hidden): a first-order *sensor lag on a model input channel* (T_ar,
T_fp) cannot be inverted without differentiating noise, so those candidates are not offered
(listed under ``skipped_candidates``) and such an effect ends as ``unexplained``. Samples are
assumed equidistant; episodes must have equal length.
"""

from evaluation.discover.arx import (
    ARXModel,
    MissingInput,
    MissingInputAdapter,
    missing_input_candidates,
)
from evaluation.discover.base import Candidate, FitResult, ModelAdapter, ParamInfo
from evaluation.discover.cli import main
from evaluation.discover.data import (
    DATASET_FORMAT,
    INDEX_COLUMNS,
    TABLE1,
    MeasuredData,
    from_arrays,
    from_batch,
    from_external,
    load_measured,
)
from evaluation.discover.fitting import ar1_inflation, fit_effects
from evaluation.discover.loop import TRAIN_FRACTION_RANGE, discover, heldout_rmse
from evaluation.discover.physics_model import (
    PHYSICS_INPUT_CHANNELS,
    PHYSICS_OUTPUT_CHANNELS,
    PhysicsCandidate,
    PhysicsModel,
    first_order_lag,
    library_candidates,
)
from evaluation.discover.report import AcceptedEffect, DiscoveryReport
from evaluation.discover.scoring import (
    LF_LIMIT,
    LF_WINDOW,
    RATIO_LIMIT,
    heldout_comparison,
    noise_levels,
    structure_statistics,
)

__all__ = [
    "DATASET_FORMAT",
    "INDEX_COLUMNS",
    "LF_LIMIT",
    "LF_WINDOW",
    "PHYSICS_INPUT_CHANNELS",
    "PHYSICS_OUTPUT_CHANNELS",
    "RATIO_LIMIT",
    "TABLE1",
    "TRAIN_FRACTION_RANGE",
    "ARXModel",
    "AcceptedEffect",
    "Candidate",
    "DiscoveryReport",
    "FitResult",
    "MeasuredData",
    "MissingInput",
    "MissingInputAdapter",
    "ModelAdapter",
    "ParamInfo",
    "PhysicsCandidate",
    "PhysicsModel",
    "ar1_inflation",
    "discover",
    "first_order_lag",
    "fit_effects",
    "from_arrays",
    "from_batch",
    "from_external",
    "heldout_comparison",
    "heldout_rmse",
    "library_candidates",
    "load_measured",
    "main",
    "missing_input_candidates",
    "noise_levels",
    "structure_statistics",
]
