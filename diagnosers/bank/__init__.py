"""A bank of relations: per monitored relation an LRGF network and an error model, trained
together, in parallel, and shared through a cache.

The rooms:

=====================  ===========================================================================
``relations``          the relations a bank models (``[output, [inputs...]]``) and their channels
``relation_bank``      :class:`~diagnosers.bank.relation_bank.RelationBank`: the trained models,
                       their centres, remaining errors and streaming state
``parallel``           training every (relation, training set) job, in this process or a pool
``relation_cache``     trained relations shared by every diagnoser of a sweep (content-addressed)
``relation_plan``      relation jobs run from outside a fit: a fit names the relations it needs
=====================  ===========================================================================
"""
