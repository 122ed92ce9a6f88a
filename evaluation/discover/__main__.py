"""``python -m evaluation.discover``: see :mod:`evaluation.discover.cli`."""

from evaluation.discover.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
