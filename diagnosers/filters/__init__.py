"""State estimators of the FCC model: innovations instead of simulation errors (issue 42).

The rooms:

=====================  ===========================================================================
``state_estimator``    :class:`FCCStateEstimator`, the unscented Kalman filter of the FCC model
                       (``filter`` a batch of episodes, ``reset`` / ``update`` a stream), and
                       its :class:`FilterResult`
``ukf_config``         :class:`UKFConfig`: the plant side, what is estimated, the tuning constants
``ukf_model``          the augmented state, its filter units, the compiled transition and
                       measurement of the FCC model, its sample function over a batch of
                       episodes or a sample of many streams
``ukf_kernels``        the filter's algebra, compiled, for any model: one sample in phases
                       around the model's transition and measurement
``ukf_linear``         the same algebra on a linear-Gaussian model: the exact Kalman filter's
                       oracle
``parameter_fit``      the model fitted to healthy records: the noise scale, parameters by the
                       augmented filter or by maximum likelihood of the innovations
``model_directions``   each fault's innovation direction from the fitted model's own
                       simulations (noise twins), never from fault data
``ukf_glr``            ``ukf-glr``, the grey-box detector: the fitted filter, a GLR per fault
                       direction and a variance CUSUM on its whitened innovations; its preset
                       ``ukf-glr-robust`` (thermocouple lags, UA_1 and A_cr estimated) and
                       ``ukf-glr-sensor`` (a sensor bias's and drift's direction per channel)
``stiction_ukf``       ``stiction-ukf``: a sticking valve by the excess variance of the model's
                       T_rx innovation about its mean (the command the valve does not follow)
=====================  ===========================================================================
"""

from diagnosers.filters.state_estimator import FCCStateEstimator, FilterResult, FilterStep
from diagnosers.filters.stiction_ukf import StictionUKF
from diagnosers.filters.ukf_config import UKFConfig
from diagnosers.filters.ukf_glr import UKFGLR

__all__ = ["UKFGLR", "FCCStateEstimator", "FilterResult", "FilterStep", "StictionUKF", "UKFConfig"]
