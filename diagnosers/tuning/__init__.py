"""Tuning a diagnoser's hyperparameters on labelled validation episodes.

The rooms:

=====================  ===========================================================================
``scorer``             the detection score of labelled episodes (:class:`DetectionScorer`), as
                       scikit-learn's scorer (``make_scorer``, ``episode_labels``), so that
                       ``GridSearchCV`` tunes any diagnoser
``grid_search``        :func:`~diagnosers.tuning.grid_search.grid_search`: a grid on held-out
                       validation episodes, scored by the scorer (scikit-learn runs the grid)
=====================  ===========================================================================
"""
