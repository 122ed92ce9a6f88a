"""Pure scores of one episode or of a set of episodes: numpy in, numbers out, no I/O.

=======================  =========================================================================
``detection_metrics``    the paper's detection indexes: :func:`r_fd`, :func:`r_td`, :func:`t_dt`,
                         :func:`episode_scores`
``isolation_metrics``    isolation indexes and the confusion matrix: :func:`t_it`, :func:`r_ti`,
                         :func:`r_fi`, :func:`cdr`, :func:`isolation_scores`
``probability_metrics``  the calibration of a posterior over hypotheses: :func:`brier_score`,
                         :func:`reliability_curve`, a hard decision's implied posterior
``intervals``            bootstrap confidence intervals, ranks with ties, ratios to a limit
=======================  =========================================================================

The detection indexes are re-exported here (``from evaluation.metrics import r_td``); the other
rooms are imported by their own names.
"""

from evaluation.metrics.detection_metrics import episode_scores, r_fd, r_td, t_dt

__all__ = ["episode_scores", "r_fd", "r_td", "t_dt"]
