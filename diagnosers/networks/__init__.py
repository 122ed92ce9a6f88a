"""The neural models: the LRGF network of IIR-filter neurons, the NNARX model-error model, and
their training.

The rooms:

=====================  ===========================================================================
``iir``                stable IIR filters as differentiable torch functions
``lrgf_net``           the LRGF network (:class:`~diagnosers.networks.lrgf_net.LRGF`)
``lrgf_fused``         its free run as one function with a hand-written backward (what trains)
``lrgf_stepper``       its sample-by-sample twin in numpy float64 (what streams)
``mem_net``            the NNARX model-error model
``mem_stepper``        the model-error model's sample-by-sample twin
``modules``            the paper's configurations; torch modules saved and loaded without pickles
``optimisers``         full-batch Adam and SPSA loops with early stopping
``training``           training the LRGF nominal model and the model-error model
``training_data``      the trainers' data: checked, standardised and stacked
=====================  ===========================================================================
"""
