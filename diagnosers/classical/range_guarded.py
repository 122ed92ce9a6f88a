"""The black-box detectors that say "new regime" instead of "fault": ``<name>-novelty``.

The classical detectors learn the healthy plant where its training history went. On the
``regimes`` track, whose set points move twice as widely as in training, they alarm on a large
share of the healthy samples (``limits`` r_fd 0.53, ``pca`` 0.32 on 100 validation episodes;
``lab/regimes-lab.md``), almost all of them while a set point is outside its training range.
Each variant here keeps every decision of its base and adds :attr:`Detection.novelty`
(:class:`~diagnosers.range_guard.RangeGuard`): a sample is novel while a set point is outside its
training range and for ``novelty_hold`` samples after. ``limits-novelty`` and ``pca-novelty``
are written out (their class names are in saved models); ``pca-empirical-novelty``,
``arx-band-novelty``, ``dpca-novelty``, ``cva-novelty`` and ``n4sid-glr-novelty`` are made by
:func:`~diagnosers.range_guard.novelty_variant`.
"""

from __future__ import annotations

from typing import Any, ClassVar

from diagnosers.classical.arx_band import ARXBand
from diagnosers.classical.cva_monitor import CVADetector
from diagnosers.classical.dpca_monitor import DPCADetector
from diagnosers.classical.limit_checker import LimitChecker
from diagnosers.classical.n4sid_glr import N4SIDGLR
from diagnosers.classical.pca_monitor import PCADetector, PCAEmpirical
from diagnosers.presets import keyword_init
from diagnosers.range_guard import NOVELTY_HOLD, RangeGuard, novelty_variant
from diagnosers.registry import register

__all__ = [
    "ARXBandNovelty",
    "CVANovelty",
    "DPCANovelty",
    "LimitsNovelty",
    "N4SIDGLRNovelty",
    "PCAEmpiricalNovelty",
    "PCANovelty",
]


@register("limits-novelty")
class LimitsNovelty(RangeGuard, LimitChecker):
    """``limits`` that flags the samples outside its training set-point range as novel.

    Args:
        alpha: as :class:`~diagnosers.classical.limit_checker.LimitChecker` (default 0.01).
        channels: as :class:`~diagnosers.classical.limit_checker.LimitChecker` (default all).
        novelty_hold: samples a novelty flag lasts after the set points return (≥ 0,
            default :data:`NOVELTY_HOLD`).
    """

    DEFAULTS: ClassVar[dict[str, Any]] = {
        "alpha": 0.01,
        "channels": None,
        "novelty_hold": NOVELTY_HOLD,
    }
    __init__ = keyword_init(DEFAULTS)


@register("pca-novelty")
class PCANovelty(RangeGuard, PCADetector):
    """``pca`` that flags the samples outside its training set-point range as novel.

    Args:
        alpha: as :class:`~diagnosers.classical.pca_monitor.PCADetector`, as are the
            following four.
        variance_explained: components kept to this share of the variance.
        n_components: or this many components.
        channels: the monitored channels.
        limits: ``"analytic"`` or ``"empirical"`` T² and SPE limits.
        novelty_hold: samples a novelty flag lasts after the set points return (≥ 0,
            default :data:`NOVELTY_HOLD`).
    """

    DEFAULTS: ClassVar[dict[str, Any]] = {**PCADetector.DEFAULTS, "novelty_hold": NOVELTY_HOLD}
    __init__ = keyword_init(DEFAULTS)


PCAEmpiricalNovelty = novelty_variant(PCAEmpirical, module=__name__)
ARXBandNovelty = novelty_variant(ARXBand, module=__name__)
DPCANovelty = novelty_variant(DPCADetector, module=__name__)
CVANovelty = novelty_variant(CVADetector, module=__name__)
N4SIDGLRNovelty = novelty_variant(N4SIDGLR, module=__name__)
