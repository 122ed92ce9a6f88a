"""Speed benchmarks, outside the library packages: each prints speed and quality figures.

=====================  ===========================================================================
``simulator_speed``    ``python -m bench.simulator_speed``: the FCC simulator
``vector_speed``       ``python -m bench.vector_speed``: the native vector env against sync
``control_speed``      ``python -m bench.control_speed``: ``FCC-control-v0`` beside
                       ``FCC-closedloop-v0``, one env, wall and CPU steps/s and their ratio
``detector_speed``     ``python -m bench.detector_speed``: the neural detector's training,
                       held-out fit and streaming throughput
``sweep_speed``        ``python -m bench.sweep_speed``: wall time of the sweep harness
``scaling``            ``python -m bench.scaling``: wall time, speed-up and serial fraction of
                       the benchmark at 1, 2, 4... workers, local or on a Ray cluster
``task_profile``       ``python -m bench.task_profile STORE``: a run's CPU per kind of task, its
                       critical path and its makespan projected on 1-16 workers, from the
                       stores' ``timings.jsonl``
``task_plan``          ``python -m bench.task_plan --track all``: every task of a leaderboard
                       run, counted without running the long ones, with sampled costs and the
                       same projection
``task_costs``         ``task_plan``'s measured part: a track at sample sizes through the real
                       drivers, timed, and a pool worker's start-up
``amdahl``             Amdahl's law and its fit (the serial fraction), for the two above and
                       ``scaling``
``loop_speed``         ``python -m bench.loop_speed``: wall time of the modelling loop
``filter_speed``       ``python -m bench.filter_speed``: the FCC state estimator, batched and
                       streaming (and filterpy's UKF beside it, if installed)
``bank_speed``         ``python -m bench.bank_speed``: ``mmae``'s 5-hypothesis filter bank,
                       streaming and in one call
=====================  ===========================================================================
"""
