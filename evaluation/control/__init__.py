"""The control task's baselines and scores (``FCC-control-v0``, :mod:`fcc_env.control_task`).

====================  ==============================================================================
``setpoints``         the best fixed set points of a plant, healthy or faulty (steady-state search)
``policies``          the baselines: the program, fixed set points, the oracle that knows the fault,
                      the diagnosis-driven supervisor
``fault_oracle``      the oracle of the whole catalogue: what it does for each process, sensor
                      and actuator fault (the study's reference)
``sensor_policy``     the supervisor that corrects a loop's set point for a stuck or biased
                      transmitter (a frozen-reading check; a diagnoser that names a sensor fault)
``hybrid_policy``     the fault-blind PPO agent, overridden by the sensor-correcting supervisor on
                      the loops it judges faulty (``ppo+sensor-correcting``)
``posterior_policy``  the supervisor on a fault posterior (``mmae``): the candidate set points of
                      highest expected return, from a table of returns per hypothesis
``policy_registry``   the policies by name: :func:`register_policy`, :func:`make_policy`,
                      :func:`available_policies` (a user's module joins with ``--import``)
``returns``           the study as a library: policies on test seeds, with intervals (data only)
``returns_report``    what it shows: the Markdown table, ``control.csv``/``.json``, the figures
``figures``           the figure of one episode per policy (return, set points, margins)
``returns_command``   ``python -m evaluation.control`` (also ``python -m evaluation.leaderboard
                      --task control``): parses, runs the study, writes, prints
``rl``                ``python -m evaluation.control.rl``: the PPO agent's command and its names
``rl_policy``         the agent's actor as arrays, saved as ``policy.npz`` + ``policy.json``
``rl_vec_env``        a Gymnasium vector env as a Stable-Baselines3 ``VecEnv``
``rl_train``          PPO training on the native vector env, and validation
``rl_command``        the ``train`` / ``evaluate`` command line
====================  ==============================================================================
"""

from evaluation.control.policy_registry import available_policies, make_policy, register_policy

__all__ = ["available_policies", "make_policy", "register_policy"]
