"""The README is a five-minute read; the rest lives in docs/, and every link resolves.

The README starts with the two commands (`make figures`, `make test`), stays within 150 lines,
lists every published artifact and holds current facts only (no dated lines). Every relative
link of the README and of docs/*.md points at a file of the repository, and docs/performance.md
holds the table benchmarks/readme_table.py writes from benchmarks/results.json.
"""

from __future__ import annotations

import importlib.util
import json
import re

import yaml

from tests.conftest import REPO

README = REPO / "README.md"
DOCS = sorted((REPO / "docs").glob("*.md"))
MAX_README_LINES = 150


def test_readme_is_short_and_opens_with_the_two_commands():
    lines = README.read_text().splitlines()
    assert len(lines) <= MAX_README_LINES, f"README.md has {len(lines)} lines"
    first_block = lines[lines.index("```bash") + 1 : lines.index("```")]
    assert [line.split()[:2] for line in first_block] == [["make", "figures"], ["make", "test"]]
    assert lines.index("```bash") < 5


def test_readme_lists_every_published_artifact():
    listed = yaml.safe_load((REPO / "workflow" / "artifacts.yaml").read_text())
    text = README.read_text()
    missing = [a for group in listed.values() for a in group if f"`{a}`" not in text]
    assert missing == []


def test_readme_holds_no_dated_lines():
    lines = README.read_text().splitlines()
    dated = [line for line in lines if re.search(r"20\d\d-\d\d-\d\d", line)]
    assert dated == []


def test_every_relative_link_resolves():
    broken = []
    for page in [README, *DOCS]:
        for target in re.findall(r"\]\(([^)#:\s]+)(?:#[^)]*)?\)", page.read_text()):
            if not (page.parent / target).exists():
                broken.append(f"{page.relative_to(REPO)} → {target}")
    assert broken == []


def test_licence_and_citation_exist():
    citation = yaml.safe_load((REPO / "CITATION.cff").read_text())
    assert citation["license"] == "MIT" and "MIT License" in (REPO / "LICENSE").read_text()
    assert citation["preferred-citation"]["title"] in README.read_text().replace("\n", " ")


def test_performance_page_holds_the_benchmark_table():
    script = REPO / "benchmarks" / "readme_table.py"
    spec = importlib.util.spec_from_file_location("readme_table", script)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    page = module.DOC.read_text()
    results = json.loads(module.RESULTS.read_text())
    assert module.with_table(page, results) == page, "rerun: python benchmarks/readme_table.py"
