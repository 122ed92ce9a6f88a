"""Sensor validation by analytical redundancy (issue 43 item 6): which sensor is faulty, and how.

The rooms:

=======================  =========================================================================
``loo_bank``             a generalised observer scheme: the FCC state estimator on all sensors and
                         one per sensor that leaves it out, run as one compiled call
``glr_bank``             a GLR bank of bias hypotheses (a constant offset on one sensor, through
                         the model's dynamics): the sensor named from an alarm's first samples
``sensor_checks``        the per-sample checks (model consistency, noise level, held values) and
                         the rule that names the sensor and the kind of its fault
``sensor_validation``    the registered ``sensor-validation`` (grey box)
=======================  =========================================================================

Importing the package registers ``sensor-validation``.
"""

from diagnosers.sensors.sensor_validation import SensorValidation

__all__ = ["SensorValidation"]
