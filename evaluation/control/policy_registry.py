"""Registry of the control study's policies: ``make_policy``, ``available_policies``,
``register_policy``.

A policy is an object with ``name`` (its row in the table), ``reset(info)`` and
``act(obs, info)`` (:class:`evaluation.control.policies.Policy`); the registry holds, by a short
name, what builds one: a class or a function. The built-ins are :data:`BUILTIN_POLICIES`:

=========================  ========================================================================
``program``                the operating program as it is (the action 0)
``fixed``                  the best fixed set points of the healthy plant
``oracle``                 knows the fault and its onset: the study's reference, always its last row
``supervisor``             a diagnosis-driven supervisor: ``make_policy("supervisor", name="pca")``
``ppo``                    a saved PPO agent: ``make_policy("ppo", directory=DIR)``
``posterior``              a supervisor on the ``mmae`` posterior: the set points of highest
                           expected return
``ppo+sensor-correcting``  a saved PPO agent whose set point on a loop the sensor-correcting
                           supervisor judges faulty is the supervisor's:
                           ``make_policy("ppo+sensor-correcting", directory=DIR)``
=========================  ========================================================================

A policy of your own joins with ``@register_policy("name")`` on its class (or on a function
that returns one) in a module that ``python -m evaluation.control --import MODULE`` imports, and
``--policies program,fixed,name`` names it (as ``--import`` does for diagnosers on the
leaderboard; the same module may register both).

This module imports nothing heavy: a built-in is imported when it is first made.

>>> [n for n in available_policies() if n in ("fixed", "oracle", "program")]
['fixed', 'oracle', 'program']
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from evaluation.control.policies import Policy

__all__ = [
    "BUILTIN_POLICIES",
    "PolicySpec",
    "available_policies",
    "make_policy",
    "policy_spec",
    "register_policy",
    "unregister_policy",
]

#: What builds a policy: a class or a function, called with the keywords of ``make_policy``.
PolicyFactory = Callable[..., "Policy"]


@dataclass(frozen=True)
class PolicySpec:
    """A registered policy: its name, what builds it, a line about it, and the keywords it
    needs (``""``: none, so that ``--policies`` may name it)."""

    name: str
    #: a class or function, or ``"module:attribute"`` for a built-in (imported on first use)
    factory: PolicyFactory | str
    summary: str = ""
    needs: str = ""


#: The study's own policies (module doc).
BUILTIN_POLICIES: tuple[PolicySpec, ...] = (
    PolicySpec(
        "program",
        "evaluation.control.policies:ProgramPolicy",
        "the operating program as it is (the action 0)",
    ),
    PolicySpec(
        "fixed",
        "evaluation.control.policies:fixed_setpoints",
        "the best fixed set points of the healthy plant",
    ),
    PolicySpec(
        "oracle",
        "evaluation.control.fault_oracle:FaultOracle",
        "knows the fault and its onset: the reference, always the last row",
    ),
    PolicySpec(
        "sensor-correcting",
        "evaluation.control.sensor_policy:SensorCorrectingSupervisor",
        "the healthy optimum, a loop's set point corrected for a stuck or biased transmitter",
    ),
    PolicySpec(
        "supervisor",
        "evaluation.control.returns:supervisor",
        "a diagnosis-driven supervisor around a registered diagnoser",
        needs="name=DIAGNOSER (the command's --diagnosers)",
    ),
    PolicySpec(
        "ppo",
        "evaluation.control.rl_policy:load_policy",
        "a saved PPO agent (policy.npz + policy.json)",
        needs="directory=DIR (python -m evaluation.control.rl evaluate --policy DIR)",
    ),
    PolicySpec(
        "ppo+sensor-correcting",
        "evaluation.control.hybrid_policy:ppo_with_sensor_correcting",
        "a saved PPO agent, overridden on the loops the sensor-correcting supervisor judges",
        needs="directory=DIR (a saved PPO agent, as for ppo)",
    ),
    PolicySpec(
        "posterior",
        "evaluation.control.posterior_policy:posterior_supervisor",
        "a supervisor on the mmae posterior: the set points of highest expected return",
    ),
)

_REGISTRY: dict[str, PolicySpec] = {spec.name: spec for spec in BUILTIN_POLICIES}


def register_policy(
    name: str, *, summary: str = "", needs: str = ""
) -> Callable[[PolicyFactory], PolicyFactory]:
    """Decorator of a class or function: ``make_policy(name, **kw)`` calls it with ``kw``.
    ``needs``: the keywords it requires, if any (a policy that needs none can be named in
    ``--policies``)."""

    def deco(factory: PolicyFactory) -> PolicyFactory:
        if not callable(factory):
            raise ValueError(
                f"register_policy({name!r}) was given {factory!r}, which is not callable; "
                "register a policy class or a function that returns a policy"
            )
        known = _REGISTRY.get(name)
        if known is not None and known.factory is not factory:
            # a module imported twice under two names (``python script.py`` runs it as
            # __main__) defines a second factory of the same name: say so
            raise ValueError(
                f"policy name {name!r} is already registered to {known.factory!r}; cannot "
                f"register {factory!r} too (choose another name, or import the module once)"
            )
        _REGISTRY[name] = PolicySpec(name, factory, summary, needs)
        return factory

    return deco


def unregister_policy(name: str) -> None:
    """Remove ``name`` (a no-op for an unknown name; a built-in comes back on re-import)."""
    _REGISTRY.pop(name, None)


def available_policies() -> list[str]:
    """Names accepted by :func:`make_policy`, sorted."""
    return sorted(_REGISTRY)


def policy_spec(name: str) -> PolicySpec:
    """The :class:`PolicySpec` registered as ``name``."""
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ValueError(
            f"Unknown policy {name!r}. Available: {available_policies()}. A policy of your own "
            "must be registered first (@register_policy in a module that python -m "
            "evaluation.control --import MODULE imports)"
        ) from None


def make_policy(name: str, /, **kwargs: Any) -> Policy:
    """Build the policy registered as ``name`` with ``kwargs``; refuses what is not a policy."""
    factory = policy_spec(name).factory
    if isinstance(factory, str):
        module, _, attribute = factory.partition(":")
        factory = getattr(importlib.import_module(module), attribute)
    policy = factory(**kwargs)
    missing = [
        a
        for a in ("name", "reset", "act")
        if not hasattr(policy, a) or (a != "name" and not callable(getattr(policy, a)))
    ]
    if missing or not isinstance(policy.name, str):
        raise ValueError(
            f"policy {name!r} built {policy!r}, which is not a policy: it lacks "
            f"{missing or ['a str name']}; a policy has name (str), reset(info) and "
            "act(obs, info) (evaluation.control.policies.Policy)"
        )
    return policy
