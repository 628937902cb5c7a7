"""The README is the first page and docs/ holds the rest (issue 25, item 8): every docs page
is in the README's index, and every relative link or image of the README and of the docs
pages names a file that exists."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from markdown_it import MarkdownIt
from markdown_it.token import Token

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _tokens(tokens: list[Token]) -> Iterator[Token]:
    for token in tokens:
        yield token
        if token.children:
            yield from _tokens(token.children)


def targets(page: Path) -> list[str]:
    """The href of every link and the src of every image of a Markdown page."""
    found = []
    for token in _tokens(MarkdownIt("commonmark").parse(page.read_text(encoding="utf-8"))):
        if token.type == "link_open":
            found.append(str(token.attrs["href"]))
        elif token.type == "image":
            found.append(str(token.attrs["src"]))
    return found


def index_section(readme: str) -> str:
    start = readme.index("\n## Documentation\n")
    end = readme.find("\n## ", start + 1)
    return readme[start : end if end >= 0 else None]


def test_every_docs_page_is_in_the_readmes_index() -> None:
    readme = ROOT / "README.md"
    index = index_section(readme.read_text(encoding="utf-8"))
    listed = {t for t in targets(readme) if t.startswith("docs/") and f"]({t})" in index}
    pages = {f"docs/{p.name}" for p in (ROOT / "docs").glob("*.md")}
    assert pages - listed == set(), "docs pages missing from the README's index"
    assert listed - pages == set(), "the index names pages that do not exist"
    # one line each: every page is named once in the index
    for page in pages:
        assert index.count(f"]({page})") == 1, page


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_and_images_exist(page: Path) -> None:
    relative = [t for t in targets(page) if "://" not in t and not t.startswith(("#", "mailto:"))]
    missing = [t for t in relative if not (page.parent / t.split("#")[0]).exists()]
    assert missing == [], f"{page.name}: links to files that do not exist"


def test_the_links_are_found() -> None:
    """The link reader sees what the pages hold (so the two tests above cannot pass empty)."""
    assert "docs/report.md" in targets(ROOT / "README.md")
    assert "report-with-hidden-effect.png" in targets(ROOT / "docs" / "report.md")
