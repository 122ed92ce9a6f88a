"""Fault isolation studies: which fault, not only whether one.

=================  ===============================================================================
``isolability``    ``python -m evaluation.isolation.isolability``: how separable the faults are
                   at the physical limit (healthy noise-free reference, before any model)
``unknown_faults`` faults no isolator was trained on (gated plant effects), to test "unknown"
``study``          ``python -m evaluation.isolation.study``: the isolators on a track's faults and
                   on unknown faults, with confusion matrices and intervals
``probabilities``  the study's probability scores: each isolator's posterior (own, or implied by
                   its decision), Brier scores per episode, the pooled reliability curve
=================  ===============================================================================

The isolation indexes themselves (CDR, t_it, r_fi, the confusion matrix) are pure functions of
:mod:`evaluation.metrics.isolation_metrics`, which the sweep records for every isolating
diagnoser.
"""
