"""Presentation of a sweep's results: tables, figures and the files a run writes.

===========  =====================================================================================
``tables``   the paper leaderboard's Markdown table, its legend and the paper's Table 2 row
``plots``    detection figures (paper Fig. 3/4 style) and confusion-matrix heat maps
``outputs``  the files of a run: ``leaderboard.md``/``.csv``, per-seed results, figures
===========  =====================================================================================
"""
