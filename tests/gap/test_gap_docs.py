"""docs/gap.md is the diagnoser's specification: every "docs/gap.md §Section" cited resolves."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SPEC = ROOT / "docs" / "gap.md"
CITING = ("dtwin", "scripts", "config", "workflow")


def _headings() -> set[str]:
    return {m.group(1).strip() for m in re.finditer(r"^#{2,4} (.+)$", SPEC.read_text(), re.M)}


def _cited_texts() -> list[tuple[str, str]]:
    """Return ``(file, text after §)`` for each § that follows "docs/gap.md" on its line."""
    found = []
    for folder in CITING:
        for path in sorted((ROOT / folder).rglob("*")):
            if not path.is_file() or path.suffix not in (".py", ".smk", ".yaml", ".md"):
                continue
            for line in path.read_text().splitlines():
                _, cited, rest = line.partition("docs/gap.md")
                if cited:
                    for text in rest.split("§")[1:]:
                        if text[:1].isupper():
                            found.append((str(path.relative_to(ROOT)), text))
    return found


def _names_a_heading(text: str, headings: set[str]) -> bool:
    return any(
        text.startswith(h) and (len(text) == len(h) or not text[len(h)].isalnum()) for h in headings
    )


def test_every_cited_section_of_docs_gap_exists():
    headings = _headings()
    citations = _cited_texts()
    assert len(citations) > 10, "docs/gap.md §Section citations not found"
    missing = [(path, text) for path, text in citations if not _names_a_heading(text, headings)]
    assert not missing, f"docs/gap.md has no heading for: {missing}"
