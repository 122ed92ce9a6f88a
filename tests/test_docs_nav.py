"""The documentation site's nav lists every lab record (``mkdocs build --strict`` refuses a
page missing from it, and that build runs only in CI: this catches it in the default run)."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_every_lab_record_is_in_the_docs_nav() -> None:
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    listed = set(re.findall(r"\blab/([\w.-]+\.md)\b", nav))
    records = {p.name for p in (ROOT / "lab").glob("*.md") if p.name != "README.md"}
    missing = sorted(records - listed)
    assert not missing, f"lab records missing from mkdocs.yml's nav: {missing}"
