"""Alarm stages: from a detector's normalised remaining errors to alarms.

The rooms:

=====================  ===========================================================================
``alarm``              the parts: residual filters (EWMA), statistics (Hotelling T², CUSUM,
                       directional GLR, projections), limit calibration and the on-delay
``alarm_stage``        :class:`~diagnosers.stages.alarm_stage.AlarmStage`, what every stage does
                       (fit, reset, step, detect, signal names, state, ``DEFAULTS``,
                       ``CONSTRAINTS``)
``ewma_stage``         ``lrgf-mem``'s stage: the paper's band rule or EWMA persistence
``directional_stage``  ``lrgf-glr``'s stage: T² and tests along fault directions
``innovation_stage``   a filter's stage: GLRs along fault directions and a variance CUSUM on
                       whitened innovations, limits on one shared tail (``ukf-glr``, the
                       reachable-bound row)
``band``               the paper's uncertainty band ``y_m + y_e ± t_α v`` and its scale
``baseline``           the held baseline a stage may remove first (running mean or regression)
``baseline_kernels``   the regression baseline's compiled per-sample steps
``operating_range``    the training range of the set points; samples outside it are novel
=====================  ===========================================================================
"""
