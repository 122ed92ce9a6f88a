"""The documentation site's generated pages (run by mkdocs-gen-files on every build).

* ``reference/detectors.md``: every registered diagnoser, read from the registry: each class
  once, rendered by mkdocstrings from its docstring, with a table of every hyperparameter and its
  default in each registry name built on that class. Nothing is typed by hand, so a renamed
  parameter or a new preset shows up at the next build.
* ``reference/tracks.md``: the published tracks, read from their definitions: the table of what
  each tests and every field of each.
* ``results.md``: the current results, copied from the tables a benchmark run wrote
  (``results/tracks/summary.md`` and ``results/tracks/<track>/leaderboard.md`` from
  ``python -m evaluation.leaderboard --track all``, ``results/leaderboard/leaderboard.md`` from
  ``python -m evaluation.leaderboard``); without them, a page saying how to produce them. The
  directory is ``results/`` or ``$FCC_RESULTS_DIR``. Figures are never typed into the docs.
* ``closed-loop.md``: the page ``docs/closed-loop.md`` with its generated parts filled in where
  it says ``<!-- generated: NAME -->``: the loops' tuning and the closed-loop observation, read
  from their definitions, and the evidence :func:`fcc_env.closed_loop_report.build_report`
  computes at every build (stability table, fault signatures, 500-episode termination count;
  the figures go to ``reference/closed-loop/``, a generated and git-ignored folder).
* ``changelog.md`` and ``lab/*.md``: the repository's ``CHANGELOG.md`` and its lab record
  (``lab/README.md`` and the ``lab/*.md`` it links to), copied as they are.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import enum
import os
import re
from pathlib import Path

import mkdocs_gen_files

import diagnosers
from evaluation.tracks import TRACKS, tracks_markdown
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS, CLOSED_LOOP_ROLES, CLOSED_LOOP_UNITS
from fcc_env.closed_loop_report import ReportConfig, build_report, signatures_note
from fcc_env.params import MEASUREMENTS
from fcc_env.regulatory import ACTUATOR_LIMITS, SETPOINT_RANGES, RegulatoryLayer

ROOT = Path(__file__).resolve().parents[1]
RESULTS = Path(os.environ.get("FCC_RESULTS_DIR", ROOT / "results"))
TRACK_ORDER = ("paper", "small", "incipient", "noisy", "uncertain", "random")
NO_RESULTS = """\
This page is generated from the tables a benchmark run writes, and none was found under
`{results}/` when the site was built. To fill it, run from the repository root (the full runs
take tens of minutes on two cores):

```bash
python -m evaluation.leaderboard --track all   # writes results/tracks/
python -m evaluation.leaderboard               # writes results/leaderboard/
python -m mkdocs build --strict
```

`FCC_RESULTS_DIR=DIR` builds the page from another results directory (one holding `tracks/`
and/or `leaderboard/`). What the columns mean is in [Tracks and reference rows](tracks.md).
"""


def copy_repository_pages() -> None:
    """The changelog and the lab record, as the repository holds them."""
    pages = {"changelog.md": ROOT / "CHANGELOG.md", "lab/index.md": ROOT / "lab" / "README.md"}
    # every record the lab folder holds, so a new record is published without a list to edit
    for source in sorted((ROOT / "lab").glob("*.md")):
        if source.name != "README.md":
            pages[f"lab/{source.name}"] = source
    for page, source in pages.items():
        with mkdocs_gen_files.open(page, "w") as f:
            f.write(source.read_text(encoding="utf-8"))
        mkdocs_gen_files.set_edit_path(page, source.relative_to(ROOT).as_posix())


def _cell(value: object) -> str:
    text = repr(value).replace("|", "\\|")
    return f"`{text}`"


def detector_reference() -> str:
    """One section per diagnoser class; a table of each registry name's defaults."""
    by_class: dict[type, list[str]] = {}
    for name in diagnosers.available():
        by_class.setdefault(diagnosers.diagnoser_class(name), []).append(name)
    lines = [
        "# Detector reference",
        "",
        "Generated from the registry (`diagnosers.available()`) at every build. Each section is "
        "one class; the table gives every hyperparameter's default under each registry name "
        "built on it (`diagnosers.make(name).get_params()`), and the class documentation below "
        "it says what each one does. See the [diagnoser guide](../diagnosers.md) for which "
        "detector to use when.",
        "",
    ]
    for cls, names in by_class.items():
        params = {name: diagnosers.make(name).get_params() for name in names}
        keys = list(dict.fromkeys(k for p in params.values() for k in p))
        lines += [f"## {', '.join(f'`{n}`' for n in names)}", ""]
        if keys:
            lines.append("| hyperparameter | " + " | ".join(f"`{n}`" for n in names) + " |")
            lines.append("|---|" + "---|" * len(names))
            for k in keys:
                row = [_cell(params[n][k]) if k in params[n] else "" for n in names]
                lines.append(f"| `{k}` | " + " | ".join(row) + " |")
        else:
            lines.append("No hyperparameters.")
        missing = _undocumented(cls, keys)
        if missing:
            lines += [
                "",
                '!!! warning "Not yet documented on the class"',
                "    " + ", ".join(f"`{k}`" for k in missing),
            ]
        lines += [
            "",
            f"::: {cls.__module__}.{cls.__qualname__}",
            "    options:",
            "      heading_level: 3",
            "      members: false",
            "",
        ]
    # The hyperparameters a family shares are documented once, on the family's base class
    # (e.g. the relation bank of every LRGF detector): render each such base once.
    registered = set(by_class)
    bases = dict.fromkeys(
        base
        for cls in by_class
        for base in cls.__mro__[1:]
        if base not in registered
        and issubclass(base, diagnosers.Diagnoser)
        and base is not diagnosers.Diagnoser
        and base.__module__.startswith("diagnosers.")
        and vars(base).get("__doc__")
        and base.__module__ not in ("diagnosers.diagnoser", "diagnosers.contract")
    )
    if bases:
        lines += ["## Shared by a family", ""]
        for base in bases:
            lines += [
                f"::: {base.__module__}.{base.__qualname__}",
                "    options:",
                "      heading_level: 3",
                "      members: false",
                "",
            ]
    return "\n".join(lines)


def track_catalogue() -> str:
    """The published tracks, read from their definitions (``evaluation.tracks.TRACKS``)."""
    tracks = list(TRACKS.values())
    fields = [
        f.name for f in dataclasses.fields(tracks[0]) if f.name not in ("name", "description")
    ]
    lines = [
        "# Track catalogue",
        "",
        "Generated from the track definitions (`evaluation.tracks.TRACKS`) at every build. What "
        "a track run reports, and against which reference rows, is in "
        "[Tracks and reference rows](../tracks.md).",
        "",
        tracks_markdown(),
        "",
        "## Definitions",
        "",
        "Every field of each published track (`None`: the paper's value for each fault).",
        "",
        "| field | " + " | ".join(f"`{t.name}`" for t in tracks) + " |",
        "|---|" + "---|" * len(tracks),
    ]
    for name in fields:
        row = [_cell(_plain(getattr(t, name))) for t in tracks]
        lines.append(f"| `{name}` | " + " | ".join(row) + " |")
    lines += ["", "::: evaluation.tracks.Track", "    options:", "      members: false", ""]
    return "\n".join(lines)


def _plain(value: object) -> object:
    """Enums by their value, so a table cell reads ``'abrupt'``, not ``<FaultProfile...>``."""
    if isinstance(value, tuple):
        return tuple(_plain(v) for v in value)
    return getattr(value, "value", value) if isinstance(value, enum.Enum) else value


def _undocumented(cls: type, names: list[str]) -> list[str]:
    """Hyperparameters named in no docstring of the class or of the classes it builds on."""
    docs = " ".join(
        vars(c).get("__doc__") or "" for c in cls.__mro__ if c is not diagnosers.Diagnoser
    )
    return [n for n in names if not re.search(rf"\b{re.escape(n)}\b", docs)]


def _without_local_links(markdown: str) -> str:
    """A results table may link its figures by relative path; the site does not carry them."""
    markdown = re.sub(r"!\[[^\]]*\]\((?!https?:)[^)]*\)", "", markdown)
    return re.sub(r"\[([^\]]*)\]\((?!https?:)[^)]*\)", r"\1", markdown)


def _demoted(markdown: str, levels: int) -> str:
    return re.sub(r"^(#+) ", lambda m: "#" * (len(m[1]) + levels) + " ", markdown, flags=re.M)


def _stamp(path: Path) -> str:
    when = dt.datetime.fromtimestamp(path.stat().st_mtime, tz=dt.UTC)
    return f"*From `{path.relative_to(RESULTS.parent)}`, written {when:%Y-%m-%d %H:%M} UTC.*"


def results_page() -> str:
    summary = RESULTS / "tracks" / "summary.md"
    paper = RESULTS / "leaderboard" / "leaderboard.md"
    lines = ["# Current results", ""]
    if not summary.is_file() and not paper.is_file():
        return "\n".join([*lines, NO_RESULTS.format(results=RESULTS.name)])
    lines += [
        "Generated at build time from the tables of the last benchmark run found under "
        f"`{RESULTS.name}/`; what the columns mean is in [Tracks and reference rows](tracks.md).",
        "",
    ]
    if summary.is_file():
        lines += ["## Every track", "", _stamp(summary), ""]
        lines += [_demoted(_without_local_links(summary.read_text(encoding="utf-8")), 2), ""]
        for track in TRACK_ORDER:
            table = RESULTS / "tracks" / track / "leaderboard.md"
            if table.is_file():
                lines += [f"### `{track}`", "", _stamp(table), ""]
                text = _without_local_links(table.read_text(encoding="utf-8"))
                lines += [_demoted(text, 3), ""]
    if paper.is_file():
        lines += ["## The paper's leaderboard", "", _stamp(paper), ""]
        lines += [_demoted(_without_local_links(paper.read_text(encoding="utf-8")), 2), ""]
    return "\n".join(lines)


def closed_loop_observation_table() -> str:
    """The closed-loop observation's channels with unit, noise and role (from the definitions)."""
    roles = {c: r for r, names in CLOSED_LOOP_ROLES.items() for c in names}
    roles["R_ar"] = "measured, manipulated (the air loop's output)"
    meas = {m.name: m for m in MEASUREMENTS}
    exact = {
        "u_F": "regenerated-catalyst slide-valve command (the T_rx loop's output)",
        "T_rx_sp": "riser outlet temperature set point",
        "T_rg1_sp": "stage-1 dense-bed temperature set point",
    }
    lines = ["| index | channel | unit | noise std | role | what |", "|---|---|---|---|---|---|"]
    for i, c in enumerate(CLOSED_LOOP_CHANNELS):
        if c in meas:
            m = meas[c]
            noise = f"{m.noise_std:.1%}" if m.noise_relative else f"{m.noise_std:g} {m.unit}"
            unit, what = m.unit, m.description
        else:
            noise, unit, what = "none (exact)", CLOSED_LOOP_UNITS[c], exact[c]
        lines.append(f"| {i} | `{c}` | {unit} | {noise} | {roles[c]} | {what} |")
    return "\n".join(lines)


def closed_loop_tuning_table() -> str:
    """Each loop's pairing, PI tuning, actuator limits and set-point range (from the defaults)."""
    layer = RegulatoryLayer()
    lines = [
        "| loop | manipulated | gain Kc | integral time τI | actuator limits | set-point range |",
        "|---|---|---|---|---|---|",
    ]
    for j, (c, u, unit) in enumerate((("T_rx", "u_F", "kg/s"), ("T_rg1", "R_ar", "t/h"))):
        lo, hi = ACTUATOR_LIMITS[j]
        sp = SETPOINT_RANGES[f"{c}_sp"]
        lines.append(
            f"| `{c}` | `{u}` | {getattr(layer, f'{c}_gain'):g} {unit}/°C | "
            f"{getattr(layer, f'{c}_integral_time_s'):g} s | {lo:.1f}–{hi:.1f} {unit} | "
            f"{sp.low:g}–{sp.high:g} °C |"
        )
    return "\n".join(lines)


#: Healthy excited episodes of the termination count on the closed-loop page (issue 31's 500).
CLOSED_LOOP_TERMINATION_EPISODES = 500
CLOSED_LOOP_FIGURES = "reference/closed-loop"


def closed_loop_page() -> str:
    """``docs/closed-loop.md`` with every ``<!-- generated: NAME -->`` marker filled in."""
    config = ReportConfig()
    report = build_report(config, terminations=CLOSED_LOOP_TERMINATION_EPISODES)
    for name in ("responses", "closed_minus_open"):
        with mkdocs_gen_files.open(f"{CLOSED_LOOP_FIGURES}/{name}.png", "wb") as f:
            f.write(getattr(report, f"{name}_png"))
    t = report.terminations or {}
    terminations = "\n".join(
        [
            "| plant | healthy excited episodes | seeds | terminations | reasons |",
            "|---|---|---|---|---|",
            *(
                f"| {loop} loop | {t['episodes']} | {t['seeds'][0]}–{t['seeds'][1]} | "
                f"{t[f'{loop}_loop']['terminations']} | "
                f"{', '.join(f'{k}: {v}' for k, v in t[f'{loop}_loop']['reasons'].items()) or '–'} |"
                for loop in ("open", "closed")
            ),
        ]
    )
    parts = {
        "tuning": closed_loop_tuning_table(),
        "observation": closed_loop_observation_table(),
        "stability": report.stability_md,
        "responses": f"![Closed-loop responses]({CLOSED_LOOP_FIGURES}/responses.png)",
        "signature-note": signatures_note(config),
        "signatures": report.signatures_md,
        "masking": report.masking_md,
        "closed-minus-open": (
            f"![Faulty − healthy, closed and open loop]({CLOSED_LOOP_FIGURES}/closed_minus_open.png)"
        ),
        "terminations": terminations,
    }
    page = (ROOT / "docs" / "closed-loop.md").read_text(encoding="utf-8")
    for name, text in parts.items():
        marker = f"<!-- generated: {name} -->"
        if marker not in page:  # a silently missing table would look like a finished page
            raise ValueError(f"docs/closed-loop.md lacks the marker {marker!r}")
        page = page.replace(marker, text)
    return page


copy_repository_pages()
with mkdocs_gen_files.open("closed-loop.md", "w") as f:
    f.write(closed_loop_page())
mkdocs_gen_files.set_edit_path("closed-loop.md", "docs/closed-loop.md")
with mkdocs_gen_files.open("reference/detectors.md", "w") as f:
    f.write(detector_reference())
with mkdocs_gen_files.open("reference/tracks.md", "w") as f:
    f.write(track_catalogue())
with mkdocs_gen_files.open("results.md", "w") as f:
    f.write(results_page())
