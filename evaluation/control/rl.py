"""``python -m evaluation.control.rl train|evaluate``: the PPO agent's command, and its names.

The command is :mod:`evaluation.control.rl_command` (its module doc: what ``train`` and
``evaluate`` do). The agent's parts, gathered here for ``from evaluation.control import rl``:

=================  ================================================================================
``rl_policy``      :class:`MLPPolicy` (the actor as arrays), :func:`save_policy`,
                   :func:`load_policy` (checked: caps, fields, finite weights, env id, hash),
                   :data:`ACTIVATIONS`, :func:`weights_sha256`
``rl_vec_env``     :func:`sb3_vec_env`: a Gymnasium vector env as an SB3 ``VecEnv``
``rl_train``       :class:`PPOSettings` (checked as SB3 and the memory budget need),
                   :func:`ppo_nbytes`, :func:`train`, :func:`export_policy`, :func:`validate`,
                   :func:`check_validation_seeds`
``rl_command``     :func:`main`: the command line
=================  ================================================================================
"""

from __future__ import annotations

from evaluation.control.rl_command import main
from evaluation.control.rl_policy import (
    ACTIVATIONS,
    FORMAT,
    MLPPolicy,
    load_policy,
    save_policy,
    weights_sha256,
)
from evaluation.control.rl_train import (
    REWARD_SCALE_USD,
    TRAIN_SEED_MIN,
    VALIDATION_SEED,
    VALIDATION_SEEDS_MAX,
    PPOSettings,
    check_validation_seeds,
    export_policy,
    ppo_nbytes,
    train,
    validate,
)
from evaluation.control.rl_vec_env import INSTALL_HINT, sb3_vec_env

__all__ = [
    "ACTIVATIONS",
    "FORMAT",
    "INSTALL_HINT",
    "REWARD_SCALE_USD",
    "TRAIN_SEED_MIN",
    "VALIDATION_SEED",
    "VALIDATION_SEEDS_MAX",
    "MLPPolicy",
    "PPOSettings",
    "check_validation_seeds",
    "export_policy",
    "load_policy",
    "main",
    "ppo_nbytes",
    "save_policy",
    "sb3_vec_env",
    "train",
    "validate",
    "weights_sha256",
]

if __name__ == "__main__":
    raise SystemExit(main())
