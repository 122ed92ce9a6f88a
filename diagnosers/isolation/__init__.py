"""Isolating diagnosers: any LRGF detector's alarms plus which fault it is.

The rooms:

======================  ==========================================================================
``isolating_detector``  :class:`~diagnosers.isolation.isolating_detector.IsolatingDetector`: the
                        inner detector, the alarm-relative features, the decision
``isolators``           the registered classifiers ``lrgf-iso`` and ``lrgf-lda``
======================  ==========================================================================

Importing the package registers the isolators.
"""

from diagnosers.isolation.isolating_detector import IsolatingDetector
from diagnosers.isolation.isolators import LRGFISO, LRGFLDA

__all__ = ["LRGFISO", "LRGFLDA", "IsolatingDetector"]
