"""Utilities shared by the three packages (``fcc_env``, ``diagnosers``, ``evaluation``).

- :mod:`fcc_common.validation`: declarative parameter constraints with one error format;
- :mod:`fcc_common.io`: the atomic file writer, the JSON scrubber and the table readers;
- :mod:`fcc_common.workers`: the set-up of every worker process (one thread, exit with parent);
- :mod:`fcc_common.safe_files`: bounded readers for files that may have been tampered with;
- :mod:`fcc_common.invocation`: the parser of every command line (its name as typed, examples);
- :mod:`fcc_common.progress`: the progress bars of the long commands (``--progress``);
- :mod:`fcc_common.import_graph`: the closure of a module's imports, read from the source (what a
  stored result's code address covers).

It depends on nothing of the project, so any package may import it without a cycle.
"""
