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
``terms``                 :class:`Term`, :class:`Factor`, :class:`TermLibrary` (user-extensible
                          candidate terms), :class:`FormCandidate`, :func:`equation`
``corrected_sim``         the declared model's simulator with a form added to its state equations
``form_search``           :class:`FormSearch`, :func:`form_round`: a form when no library effect
                          explains the residual (PySINDy's STLSQ over simulated sensitivities,
                          the held-out gate, a stability check)
``form_shapes``           :func:`refine_shapes`: a selected form's centres, scales and time
                          constants fitted with its coefficients (simulation error, bounded)
``scoring``               :func:`heldout_comparison`, :func:`structure_statistics`
``drift``                 the unmeasured feed-coking drift of closed-loop data, estimated by the
                          state estimator, gated, and fed to the model before the search
``drift_joint``           the drift estimate's level and trend as nuisance parameters fitted with
                          every candidate (``drift_fit="joint"``)
``selection``             the accepted effects (a nuisance entry among them) and their joint
                          re-fit and backward elimination
``loop``                  :func:`discover`
``report``                :class:`DiscoveryReport`, residual tests and plots of the report
``residual_tests``        whiteness, bias, drift and correlation tests of a residual
``cli``                   ``python -m evaluation.discover`` (its wall time: ``python -m bench.loop_speed``)
========================  =========================================================================

When structure remains that no library effect explains, the loop searches for a *form*: a
sparse correction of at most three terms to one state equation or measurement, gated like a
library effect and reported as an equation (``--forms``, :class:`FormSearch`); a report's
effects and forms are accepted into the model with ``--accept DIR/report.json``
(``PhysicsModel(declared=declared_from_report(...))``).

On closed-loop data (``MeasuredData.closed_loop``) the loop first estimates the unmeasured
feed-coking drift and feeds it to the model as a known input (``drift="auto"``; the report's
``drift`` section and ``drift.png`` show it; ``--drift off`` turns it off). The estimate's level and trend are then
fitted again with every candidate (``drift_fit="joint"``, ``--drift-fit``), so a level or trend
that an effect leaked into the estimate goes back to the effect.

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
from evaluation.discover.form_search import FormSearch, form_round, stability
from evaluation.discover.form_shapes import refine_shapes, shape_parameters, with_shapes
from evaluation.discover.loop import TRAIN_FRACTION_RANGE, discover, heldout_rmse
from evaluation.discover.physics_model import (
    PHYSICS_INPUT_CHANNELS,
    PHYSICS_OUTPUT_CHANNELS,
    PhysicsCandidate,
    PhysicsModel,
    declared_from_report,
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
from evaluation.discover.terms import (
    Factor,
    FormCandidate,
    Term,
    TermLibrary,
    equation,
    form_from_json,
    form_to_json,
    shape_slots,
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
    "Factor",
    "FitResult",
    "FormCandidate",
    "FormSearch",
    "MeasuredData",
    "MissingInput",
    "MissingInputAdapter",
    "ModelAdapter",
    "ParamInfo",
    "PhysicsCandidate",
    "PhysicsModel",
    "Term",
    "TermLibrary",
    "ar1_inflation",
    "declared_from_report",
    "discover",
    "equation",
    "first_order_lag",
    "fit_effects",
    "form_from_json",
    "form_round",
    "form_to_json",
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
    "refine_shapes",
    "shape_parameters",
    "shape_slots",
    "stability",
    "structure_statistics",
    "with_shapes",
]
