"""The control task's baselines and scores (``FCC-control-v0``, :mod:`fcc_env.control_task`).

================  ================================================================================
``setpoints``     the best fixed set points of a plant, healthy or faulty (steady-state search)
``policies``      the baselines: the program, fixed set points, the oracle that knows the fault
``returns``       ``python -m evaluation.control``: the baselines on test seeds, with intervals
================  ================================================================================
"""
