"""``python -m evaluation.control.rl train|evaluate``: the PPO agent's command, and its names.

The command is :mod:`evaluation.control.rl_command` (its module doc: what ``train`` and
``evaluate`` do). The agent's parts, gathered here for ``from evaluation.control import rl``:

=================  ================================================================================
``rl_policy``      :class:`MLPPolicy` (the actor as arrays), :func:`save_policy`,
                   :func:`load_policy`
``rl_vec_env``     :func:`sb3_vec_env`: a Gymnasium vector env as an SB3 ``VecEnv``
``rl_train``       :class:`PPOSettings`, :func:`train`, :func:`export_policy`, :func:`validate`
``rl_command``     :func:`main`: the command line
=================  ================================================================================
"""

from __future__ import annotations

from evaluation.control.rl_command import main
from evaluation.control.rl_policy import FORMAT, MLPPolicy, load_policy, save_policy
from evaluation.control.rl_train import (
    REWARD_SCALE_USD,
    TRAIN_SEED_MIN,
    VALIDATION_SEED,
    PPOSettings,
    export_policy,
    train,
    validate,
)
from evaluation.control.rl_vec_env import INSTALL_HINT, sb3_vec_env

__all__ = [
    "FORMAT",
    "INSTALL_HINT",
    "REWARD_SCALE_USD",
    "TRAIN_SEED_MIN",
    "VALIDATION_SEED",
    "MLPPolicy",
    "PPOSettings",
    "export_policy",
    "load_policy",
    "main",
    "save_policy",
    "sb3_vec_env",
    "train",
    "validate",
]

if __name__ == "__main__":
    raise SystemExit(main())
