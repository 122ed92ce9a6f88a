"""``python -m evaluation.control.rl``: a PPO agent (Stable-Baselines3) on ``FCC-control-v0``.

``train`` runs SB3's PPO (``MlpPolicy``) on the native vector env
(:class:`~fcc_env.control_vector.FCCControlVectorEnv`, random faults per episode) for at most
``--minutes`` of wall clock, on training seeds only (``--seed`` ≥ 1000, every env below the
validation seeds 5000..), then scores the deterministic policy on ``--val-seeds`` validation
episodes per scenario (seeds 5000..) beside the best fixed set points. ``evaluate`` adds the
saved agent to the control study (:mod:`evaluation.control.returns_command`, test seeds 0..): the
same harness and table as the baselines, with its loss against the oracle.

The agent sees the observation scaled by running statistics (SB3's ``VecNormalize``, frozen
when saved) and the reward divided by
:data:`~evaluation.control.rl_train.REWARD_SCALE_USD`. The saved policy is ``policy.npz`` (the
actor's weights, no pickle) and ``policy.json`` (architecture, scaling, action bounds, the
training settings): loading runs no code from the files and needs neither SB3 nor torch.
Stable-Baselines3 is an optional extra: ``pip install -e ".[rl]"``. Progress bars (``train``:
env steps and the mean return of the last episodes; the validation and study episodes) go to
standard error when it is a terminal, or with ``--progress``; ``--no-progress`` turns them off.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path

from evaluation.control import returns_command
from evaluation.control.policy_registry import make_policy
from evaluation.control.rl_policy import save_policy
from evaluation.control.rl_train import PPOSettings, check_validation_seeds, train, validate
from evaluation.control.rl_vec_env import require_sb3
from fcc_common.invocation import check_out_path, command_parser, out_path, run_command
from fcc_common.io import atomic_write_json
from fcc_common.progress import add_progress_flag
from fcc_common.validation import invalid

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> int:
    parser = command_parser(
        "evaluation.control.rl",
        __doc__ or "",
        (
            ("train --minutes 30 --seed 1000 --out results/rl", "the 30-minute agent"),
            ("evaluate --policy results/rl --seeds 20 --out results/control_rl", "the study"),
        ),
    )
    sub = parser.add_subparsers(dest="command", required=True)
    # a subcommand's parser is argparse's own, which reads abbreviations unless told not to
    t = sub.add_parser("train", help="train PPO on the native vector env", allow_abbrev=False)
    d = PPOSettings()
    t.add_argument("--minutes", type=float, default=d.minutes, help="wall-clock budget (30)")
    t.add_argument("--envs", type=int, default=d.envs, help=f"vector envs ({d.envs})")
    t.add_argument("--seed", type=int, default=d.seed, help="first training seed (1000)")
    t.add_argument("--n-steps", type=int, default=d.n_steps, help="steps per env per rollout")
    t.add_argument("--batch-size", type=int, default=d.batch_size)
    t.add_argument("--n-epochs", type=int, default=d.n_epochs)
    t.add_argument("--lr", type=float, default=d.learning_rate, help="learning rate")
    t.add_argument("--gamma", type=float, default=d.gamma)
    t.add_argument("--hidden", default="64,64", help="layer widths of actor and critic")
    t.add_argument("--reward-scale", type=float, default=d.reward_scale_usd, help="USD")
    t.add_argument("--max-env-steps", type=int, default=None, help="stop earlier, at this many")
    t.add_argument("--torch-threads", type=int, default=d.torch_threads)
    t.add_argument("--val-seeds", type=int, default=2, help="validation seeds per scenario")
    t.add_argument(
        "--catalogue",
        default=d.catalogue,
        help="what the episodes draw: paper (f1-f4) or sensor (healthy or a sensor fault), on "
        "the native vector env; all (every fault class, Python envs: ten times slower)",
    )
    t.add_argument("--out", type=out_path, required=True)
    add_progress_flag(t)
    e = sub.add_parser(
        "evaluate", help="the saved agent in the control study (test seeds)", allow_abbrev=False
    )
    e.add_argument("--policy", type=Path, required=True, help="a train --out directory")
    e.add_argument("--seeds", type=int, default=20)
    e.add_argument("--steps", type=int, default=3999)
    e.add_argument("--diagnosers", default="", help="supervisors too (as evaluation.control)")
    e.add_argument(
        "--diagnoser-params", default="{}", metavar="JSON", help="as evaluation.control's"
    )
    e.add_argument("--out", type=out_path, default=Path("results/control_rl"))
    add_progress_flag(e)
    return run_command(parser, _run, argv)


def _run(args: argparse.Namespace) -> int:
    if args.command == "evaluate":
        policy = make_policy("ppo", directory=args.policy)
        study = ["--seeds", str(args.seeds), "--steps", str(args.steps), "--out", str(args.out)]
        study += ["--diagnosers", args.diagnosers, "--diagnoser-params", args.diagnoser_params]
        if args.progress is not None:
            study.append("--progress" if args.progress else "--no-progress")
        return returns_command.main(study, extra_policies=[policy])
    try:
        hidden = tuple(int(h) for h in args.hidden.split(","))
    except ValueError:
        raise invalid("--hidden", args.hidden, "comma-separated integers, e.g. 64,64") from None
    check_validation_seeds(args.val_seeds)
    settings = PPOSettings(
        minutes=args.minutes,
        envs=args.envs,
        seed=args.seed,
        n_steps=args.n_steps,
        batch_size=args.batch_size,
        n_epochs=args.n_epochs,
        learning_rate=args.lr,
        gamma=args.gamma,
        hidden=hidden,
        reward_scale_usd=args.reward_scale,
        max_env_steps=args.max_env_steps,
        torch_threads=args.torch_threads,
        catalogue=args.catalogue,
    )
    check_out_path("--out", args.out)
    require_sb3()
    policy, log = train(settings, progress=args.progress)
    save_policy(args.out, policy)
    if args.val_seeds:
        log["validation"] = validate(policy, args.val_seeds, progress=args.progress)
    atomic_write_json(args.out / "training.json", log)
    print(
        f"{log['env_steps']:,} env steps in {log['seconds']:.0f} s "
        f"({log['env_steps_per_s']:,.0f}/s); wrote {args.out} (policy.npz, policy.json, "
        "training.json)"
    )
    if args.val_seeds:
        print(json.dumps(log["validation"], indent=1))
    return 0
