"""Classical detectors, the baselines of the leaderboard: fixed limits, PCA (T² + SPE), an
ARX output-error band, and the field's standard black-box monitors of dynamic data (dynamic
PCA, canonical variate analysis, a subspace-identified Kalman predictor with a GLR).

All learn from healthy episodes only and decide with a confidence level ``1 - alpha``
(``alpha = 0.01`` as in the paper). They give the neural detectors a yardstick:

* ``limits``   - :class:`LimitChecker`: per-channel ``mean ± t_α·std`` limits.
* ``pca``      - :class:`PCADetector`: Hotelling T² and SPE (Q) on standardised measurements;
  ``pca-empirical`` (:class:`PCAEmpirical`) sets both limits at the training data's percentile.
* ``limits-novelty``, ``pca-novelty``, ``pca-empirical-novelty``, ``arx-band-novelty``,
  ``dpca-novelty``, ``cva-novelty``, ``n4sid-glr-novelty`` - each the same as its base, flagging
  samples outside the training set-point range as novel (:mod:`diagnosers.classical.range_guarded`).
* ``arx-band`` - :class:`ARXBand`: a linear ARX model of ``T_rx`` from ``T_rg2`` and ``T_fp``
  (the paper's relation (14)) run in simulation, with a band ``y_m ± t_α·σ``.
* ``dpca``     - :class:`DPCADetector`: T² and Q of the lagged channels (Ku et al. 1995).
* ``cva``      - :class:`CVADetector`: T² of the canonical states and of the rest (Russell,
  Chiang & Braatz 2000).
* ``n4sid-glr`` - :class:`N4SIDGLR`: an N4SID-identified Kalman predictor, a GLR on its
  whitened innovations along fault directions learned from labelled training faults.

The rooms:

=====================  ===========================================================================
``limit_checker``      ``limits``: per-channel limits
``pca_monitor``        ``pca`` and ``pca-empirical``: T² and SPE on standardised measurements
``arx_band``           ``arx-band``: the ARX output-error band
``range_guarded``      the ``<name>-novelty`` variants: the same decisions, plus the samples
                       outside the training set-point range flagged as novel, not as faults
``channel_selection``  what they share: the channels they watch and their significance level
``subspace``           the algebra of the dynamic monitors: lagged vectors, canonical variates,
                       Larimore's AIC, N4SID in innovation form
``lagged_monitor``     what ``dpca`` and ``cva`` share: lagged vectors, T² and Q, empirical limits
``dpca_monitor``       ``dpca``: dynamic PCA
``cva_monitor``        ``cva``: canonical variate analysis
``n4sid_glr``          ``n4sid-glr``: the identified Kalman predictor and its GLR
=====================  ===========================================================================
"""

from diagnosers.classical.arx_band import ARXBand, fit_percent
from diagnosers.classical.cva_monitor import CVADetector
from diagnosers.classical.dpca_monitor import DPCADetector
from diagnosers.classical.limit_checker import LimitChecker
from diagnosers.classical.n4sid_glr import N4SIDGLR
from diagnosers.classical.pca_monitor import (
    PCADetector,
    PCAEmpirical,
    hotelling_t2_limit,
    spe_limit,
)
from diagnosers.classical.range_guarded import (
    ARXBandNovelty,
    CVANovelty,
    DPCANovelty,
    LimitsNovelty,
    N4SIDGLRNovelty,
    PCAEmpiricalNovelty,
    PCANovelty,
)

__all__ = [
    "N4SIDGLR",
    "ARXBand",
    "ARXBandNovelty",
    "CVADetector",
    "CVANovelty",
    "DPCADetector",
    "DPCANovelty",
    "LimitChecker",
    "LimitsNovelty",
    "N4SIDGLRNovelty",
    "PCADetector",
    "PCAEmpirical",
    "PCAEmpiricalNovelty",
    "PCANovelty",
    "fit_percent",
    "hotelling_t2_limit",
    "spe_limit",
]
