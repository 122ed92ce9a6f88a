"""Classical detectors, the baselines of the leaderboard: fixed limits, PCA (T² + SPE) and an
ARX output-error band.

All learn from healthy episodes only and decide with a confidence level ``1 - alpha``
(``alpha = 0.01`` as in the paper). They give the neural detectors a yardstick:

* ``limits``   - :class:`LimitChecker`: per-channel ``mean ± t_α·std`` limits.
* ``pca``      - :class:`PCADetector`: Hotelling T² and SPE (Q) on standardised measurements;
  ``pca-empirical`` (:class:`PCAEmpirical`) sets both limits at the training data's percentile.
* ``limits-novelty``, ``pca-novelty`` - the same, flagging samples outside the training set-point
  range as novel (:mod:`diagnosers.classical.range_guarded`).
* ``arx-band`` - :class:`ARXBand`: a linear ARX model of ``T_rx`` from ``T_rg2`` and ``T_fp``
  (the paper's relation (14)) run in simulation, with a band ``y_m ± t_α·σ``.

The rooms:

=====================  ===========================================================================
``limit_checker``      ``limits``: per-channel limits
``pca_monitor``        ``pca`` and ``pca-empirical``: T² and SPE on standardised measurements
``arx_band``           ``arx-band``: the ARX output-error band
``range_guarded``      ``limits-novelty``, ``pca-novelty``: the same decisions, plus the samples
                       outside the training set-point range flagged as novel, not as faults
``channel_selection``  what they share: the channels they watch and their significance level
=====================  ===========================================================================
"""

from diagnosers.classical.arx_band import ARXBand, fit_percent
from diagnosers.classical.limit_checker import LimitChecker
from diagnosers.classical.pca_monitor import (
    PCADetector,
    PCAEmpirical,
    hotelling_t2_limit,
    spe_limit,
)
from diagnosers.classical.range_guarded import LimitsNovelty, PCANovelty

__all__ = [
    "ARXBand",
    "LimitChecker",
    "LimitsNovelty",
    "PCADetector",
    "PCAEmpirical",
    "PCANovelty",
    "fit_percent",
    "hotelling_t2_limit",
    "spe_limit",
]
