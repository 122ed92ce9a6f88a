"""``python -m evaluation.control``: see :mod:`evaluation.control.returns_command`."""

from evaluation.control.returns_command import main

if __name__ == "__main__":
    raise SystemExit(main())
