"""Isolating diagnosers: any LRGF detector's alarms plus which fault it is, or a bank of
filters' probability of each fault.

The rooms:

=======================  ==========================================================================
``isolating_detector``   :class:`~diagnosers.isolation.isolating_detector.IsolatingDetector`: the
                         inner detector, the alarm-relative features, the decision
``isolators``            the registered classifiers ``lrgf-iso`` and ``lrgf-lda``
``filter_bank``          a bank of FCC state estimators, one per hypothesis, run as one compiled
                         call, and their multiple-model posterior
``mmae``                 the registered ``mmae``: the bank's posterior per hypothesis, its alarm
                         and diagnosis (isolation with probabilities, grey box)
``catalogue_isolator``  the registered ``catalogue-isolator``: specialised isolators side by side,
                         each confirming its own fault, so that two faults are named (grey box)
``catalogue_members``    its members: how a member's word is read, what a member spec may hold
``composition``          its per-sample rule: confirmation, hold, deferral, the answer
=======================  ==========================================================================

Importing the package registers the isolators.
"""

from diagnosers.isolation.catalogue_isolator import CatalogueIsolator
from diagnosers.isolation.isolating_detector import IsolatingDetector
from diagnosers.isolation.isolators import LRGFISO, LRGFLDA
from diagnosers.isolation.mmae import MMAE

__all__ = ["LRGFISO", "LRGFLDA", "MMAE", "CatalogueIsolator", "IsolatingDetector"]
