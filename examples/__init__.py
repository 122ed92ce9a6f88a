"""Worked examples of plugging into the library (not installed with the packages).

``examples`` is a package so that its modules are importable by dotted name from the repository
root, e.g. ``python -m evaluation.leaderboard --import examples.cusum_diagnoser``.
"""
