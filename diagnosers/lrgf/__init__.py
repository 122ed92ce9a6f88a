"""The LRGF detectors: a bank of relations, an alarm stage and optional parts, composed.

The rooms:

=====================  ===========================================================================
``bank_detector``      :class:`~diagnosers.lrgf.bank_detector.BankDetector`: what every LRGF
                       detector shares (the bank's hyperparameters, training, running it with
                       an alarm stage, persistence)
``lrgf_mem``           ``lrgf-mem``: the paper's detector with an EWMA stage
``lrgf_glr``           ``lrgf-glr``: a cross-fitted limit and tests along fault directions
``lrgf_presets``       the registered variants (``lrgf-mem-paper``, ``lrgf-glr-adaptive``, ...,
                       ``lrgf-glr-closed-novelty``)
``fault_directions``   where each fault moves the remaining error (``lrgf-glr``'s directions),
                       learned from the labelled faults passed to ``fit`` and their noise twins
``novelty``            how far a model's prediction lies outside its training range
=====================  ===========================================================================

Importing the package registers the detectors.
"""

from diagnosers.lrgf import lrgf_glr, lrgf_mem, lrgf_presets  # noqa: F401  (registers them)
from diagnosers.lrgf.bank_detector import BankDetector
from diagnosers.lrgf.lrgf_glr import LRGFGLR
from diagnosers.lrgf.lrgf_mem import LRGFMEM

__all__ = ["LRGFGLR", "LRGFMEM", "BankDetector"]
