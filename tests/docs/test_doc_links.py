"""The README, CHANGELOG and docs pages point at things that exist: every repository path
they name in backticks (`fcu/control/tracker.py`, `config/scenarios/`, `fcu/control/tracker.py`
(`Name`)...) and every relative link, anchors included, so a moved module or a renamed section
cannot leave a page pointing at nothing."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", ROOT / "CHANGELOG.md", *sorted((ROOT / "docs").glob("*.md"))]
TOP = ("common", "fcu", "sitl", "gcs", "config", "benchmarks", "tests", "docs", "tools")
PATH = re.compile(r"`((?:" + "|".join(TOP) + r")/[A-Za-z0-9_./*-]*)")
LINK = re.compile(r"\]\(([^)\s]+)\)")


def _slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)
    return {_slug(m.group(1)) for m in re.finditer(r"^#+ (.+)$", text, flags=re.M)}


def _named_paths(page: Path) -> list[str]:
    text = page.read_text()
    return sorted({m.group(1).rstrip(".") for m in PATH.finditer(text)})


def test_the_scan_finds_paths_and_links():
    """Given the README, then the scan finds paths and links in it (so silence means
    something), and the slug rule gives GitHub's anchors."""
    assert len(_named_paths(ROOT / "README.md")) > 5
    assert LINK.findall((ROOT / "README.md").read_text())
    assert _slug("How the paper's ambiguities were resolved") == \
        "how-the-papers-ambiguities-were-resolved"
    assert _slug("Allocation that knows its actuators (CA_LAG_COMP)") == \
        "allocation-that-knows-its-actuators-ca_lag_comp"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_named_paths_exist(page):
    """Given a page, then every repository path it names exists (globs match something)."""
    missing = [p for p in _named_paths(page) if "/." not in p  # made on first use, ignored
               and not (list(ROOT.glob(p)) if "*" in p else (ROOT / p).exists())]
    assert missing == []


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_and_anchors_exist(page):
    """Given a page, then every relative link reaches a file, and its #anchor a heading."""
    broken = []
    for target in LINK.findall(page.read_text()):
        if re.match(r"[a-z]+:", target):  # https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        if not file.exists():
            broken.append(target)
        elif anchor and file.suffix == ".md" and anchor not in _anchors(file):
            broken.append(target)
    assert broken == []


CODE = [p for top in ("common", "fcu", "sitl", "gcs", "config", "benchmarks", "tests", "tools")
        for p in sorted((ROOT / top).rglob("*")) if p.suffix in (".py", ".toml")]
CITED = re.compile(r"docs/([a-z0-9_-]+\.md)(?:#([a-z0-9_-]+))?")
NOTES = re.compile(r"\b(?:MODEL|DESIGN|SENSORS|MAVLINK)\.md\b")


def test_the_code_cites_pages_and_sections_that_exist():
    """Given every module and config file, then each page of docs/ it cites (`docs/model.md`,
    `docs/model.md#dynamics`) exists with that section, and none cites a note that is not in
    the repository (MODEL.md and the like, which a reader of the code cannot open)."""
    broken, foreign, cited = [], [], 0
    for path in CODE:
        text = path.read_text(errors="replace")
        where = str(path.relative_to(ROOT))
        foreign += [f"{where}: {m.group(0)}" for m in NOTES.finditer(text)
                    if path.name != "test_doc_links.py"]
        for page, anchor in CITED.findall(text):
            cited += 1
            target = ROOT / "docs" / page
            if not target.exists() or (anchor and anchor not in _anchors(target)):
                broken.append(f"{where}: docs/{page}" + (f"#{anchor}" if anchor else ""))
    assert cited > 40 and broken == [] and foreign == []
