"""Evaluation of diagnosers: pure metrics (:mod:`evaluation.metrics`), harness, leaderboard, plots.

Kept free of heavy imports so that ``import evaluation.metrics`` stays cheap.
"""
