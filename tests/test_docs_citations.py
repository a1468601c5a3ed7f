"""Every citation of the docs names a page and a section that exist, and nothing cites a document outside the
repository.

A citation is ``docs/PAGE.md`` (in code, tests, benchmarks, configs and docs) or a Markdown link
``[text](PAGE.md)`` (within docs/), optionally followed by quoted sections: ``docs/contracts.md, "Exit codes"``,
``[harness.md](harness.md), "Sync pairing" and "Alignment"``. A section is found when the page has a Markdown
heading that is the section, or starts with it followed by `` (``: ``"Sync pairing"`` names
``## Sync pairing (`hil/pipeline/sync_pairing.py`)``; a numbered item's bold lead-in (``10. **Cost.**``)
counts as a heading.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
SCANNED_DIRS = ("hil", "drivers", "emulators", "tests", "benchmarks", "configs", "docs")
SCANNED_FILES = ("README.md", "pyproject.toml")
SUFFIXES = {".py", ".md", ".yaml", ".yml", ".toml", ".dbc", ".txt"}
# the outside design document and the directory beside the repository it lived in (this file names them to
# forbid them, so it is not scanned for them)
FORBIDDEN = ("DESIGN.md", "../shared", "/work/shared")

QUOTED = r'"([^"]{1,120})"'
CITATION = re.compile(
    r"(?:\bdocs/|\]\()([A-Za-z0-9_-]+\.md)\)?`?"  # docs/PAGE.md, `docs/PAGE.md` or [text](PAGE.md)
    rf"(?:,?\s+{QUOTED}((?:(?:\s*,\s*|\s+and\s+){QUOTED})*))?"
)
HEADING = re.compile(r"^#{1,6}\s+(.+?)\s*#*\s*$", re.MULTILINE)
LEAD_IN = re.compile(r"^\s*\d+\.\s+\*\*(.+?)\.?\*\*", re.MULTILINE)


def _plain(text: str) -> str:
    return " ".join(text.split())


def sections(page_text: str) -> list[str]:
    """The headings (and numbered items' bold lead-ins) of a Markdown page, whitespace collapsed."""
    return [_plain(h) for h in HEADING.findall(page_text) + LEAD_IN.findall(page_text)]


def has_section(headings: list[str], section: str) -> bool:
    section = _plain(section)
    return any(h == section or h.startswith(section + " (") for h in headings)


def citations(text: str) -> list[tuple[str, list[str]]]:
    """(page, [sections]) of every citation in ``text``."""
    found = []
    for match in CITATION.finditer(text):
        page, first, rest = match.group(1), match.group(2), match.group(3) or ""
        cited = ([first] if first else []) + re.findall(QUOTED, rest)
        found.append((page, cited))
    return found


def broken_citations(text: str, pages: dict[str, str]) -> list[str]:
    """A line for every citation of ``text`` whose page (a name in ``pages``, name -> text) or section is missing."""
    problems = []
    for page, cited in citations(text):
        if page not in pages:
            problems.append(f"{page}: no such page in docs/")
            continue
        headings = sections(pages[page])
        problems += [f'{page}, "{s}": no such heading' for s in cited if not has_section(headings, s)]
    return problems


def _scanned() -> list[Path]:
    files = [ROOT / name for name in SCANNED_FILES]
    for folder in SCANNED_DIRS:
        files += sorted(p for p in (ROOT / folder).rglob("*") if p.suffix in SUFFIXES and p.is_file())
    return [p for p in files if p.exists() and p.resolve() != Path(__file__).resolve()]


def _pages() -> dict[str, str]:
    return {p.name: p.read_text(encoding="utf-8") for p in DOCS.glob("*.md")}


def test_every_citation_names_an_existing_page_and_heading():
    pages = _pages()
    problems = []
    for path in _scanned():
        problems += [f"{path.relative_to(ROOT)}: {p}" for p in broken_citations(path.read_text(encoding="utf-8"), pages)]
    assert not problems, "\n".join(problems)


def test_the_code_cites_the_contract_pages():
    cited = {(page, s) for path in _scanned() for page, names in citations(path.read_text(encoding="utf-8"))
             for s in names}
    for expected in [("contracts.md", "result.json"), ("contracts.md", "Exit codes"), ("design.md", "Layers"),
                     ("wire-formats.md", "KVH 1750"), ("contracts.md", "noise.json")]:
        assert expected in cited


def test_nothing_cites_a_document_outside_the_repository():
    offenders = [f"{path.relative_to(ROOT)}: {word}" for path in _scanned()
                 for word in FORBIDDEN if word in path.read_text(encoding="utf-8")]
    assert not offenders, "\n".join(offenders)


def test_a_missing_heading_or_page_is_reported_and_a_present_one_is_not():
    pages = {"a.md": "# A\n\n## Sync pairing (`x.py`)\n\n1. **Cost.** cheap\n", "b.md": "# B\n"}
    text = ('see docs/a.md, "Sync pairing" and "Cost"; docs/a.md, "Sync"; [b](b.md), "Nope"; docs/c.md; '
            '`docs/a.md`, "Sync\n   pairing"')
    assert broken_citations(text, pages) == ['a.md, "Sync": no such heading', 'b.md, "Nope": no such heading',
                                             "c.md: no such page in docs/"]
    assert citations(text)[0] == ("a.md", ["Sync pairing", "Cost"])
