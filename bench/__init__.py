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
``loop_speed``         ``python -m bench.loop_speed``: wall time of the modelling loop
``filter_speed``       ``python -m bench.filter_speed``: the FCC state estimator, batched and
                       streaming (and filterpy's UKF beside it, if installed)
``bank_speed``         ``python -m bench.bank_speed``: ``mmae``'s 5-hypothesis filter bank,
                       streaming and in one call
=====================  ===========================================================================
"""
