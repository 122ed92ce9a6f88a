"""Locally recurrent globally feed-forward (LRGF) network with IIR-filter neurons.

This is the dynamic network of Section 2 of the paper (eqs (1)-(8)): ``v`` hidden neurons, each a
weighted sum of the ``n`` inputs followed by an ``r``-th order IIR filter in companion state-space
form and a sloped, biased tanh; a linear output layer maps the ``v`` neuron outputs to ``m``
outputs.

Each neuron is a linear SISO filter followed by a static nonlinearity, so the network is evaluated
without any per-time-step Python loop: :class:`IIRFilterFunction` runs ``scipy.signal.lfilter``
over whole sequences and back-propagates with ``lfilter`` on time-reversed signals (the dynoNet
approach). Stability holds for every parameter value because the filter denominators are built
from reflection coefficients ``|k_j| < 1`` (Levinson/Schur step-up recursion).

Tensors are batch-first, ``(batch, time, channels)``. Filtering is done in float64 internally
whatever the module dtype; outputs come back in the input's dtype.

The implementation is split by job: :mod:`diagnosers.iir` (the differentiable filter and the
stable parametrisation), :mod:`diagnosers.lrgf_net` (the layer) and :mod:`diagnosers.lrgf_stepper`
(numpy streaming). This module re-exports their public names.
"""

from diagnosers.iir import (
    IIRFilterFunction,
    denominator_from_reflection,
    iir_filter,
    numerator_from_state_space,
    reflection_from_denominator,
)
from diagnosers.lrgf_net import LRGF, InitialState, lrgf_activation, set_scaler_buffers
from diagnosers.lrgf_stepper import LRGFStepper, NeuronFilters, filter_step

__all__ = [
    "LRGF",
    "IIRFilterFunction",
    "InitialState",
    "LRGFStepper",
    "NeuronFilters",
    "denominator_from_reflection",
    "filter_step",
    "iir_filter",
    "lrgf_activation",
    "numerator_from_state_space",
    "reflection_from_denominator",
    "set_scaler_buffers",
]
