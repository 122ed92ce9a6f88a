"""``python -m evaluation.leaderboard``: see :mod:`evaluation.leaderboard.command`."""

from evaluation.leaderboard.command import main

if __name__ == "__main__":
    raise SystemExit(main())
