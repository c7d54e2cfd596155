"""The documentation's links: every relative link and picture in README.md and the pages
under docs/ points at a file of the repository, and an anchor at a heading of its page."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]

LINK = re.compile(r"!?\[(?:[^\]\[]|\[[^\]]*\])*\]"      # [text], one level of [] inside
                  r"\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")   # (target "title")
FENCE = re.compile(r"^\s*(```|~~~)")
EXTERNAL = re.compile(r"^[a-z][a-z0-9+.-]*:", re.I)      # http:, https:, mailto: ...


def _prose(text: str, *, inline_code: bool = False) -> list[str]:
    """The lines of a page outside code: fenced blocks and indented blocks dropped,
    inline code blanked unless ``inline_code``."""
    lines, fenced, previous = [], False, ""
    for line in text.splitlines():
        if FENCE.match(line):
            fenced = not fenced
            continue
        indented = line.startswith("    ") and not previous.strip()
        code_block = (indented and not re.match(r"\s*([-*]|\d+\.)\s", line.lstrip()))
        if not fenced and not (code_block and line.strip()):
            lines.append(line if inline_code else re.sub(r"`[^`]*`", "``", line))
        previous = line if not code_block else ""
    return lines


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, links reduced to their text,
    punctuation dropped, spaces as hyphens."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip()).lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """The anchors of a page's headings (a repeated heading gets -1, -2, ...)."""
    found, seen = set(), {}
    for line in _prose(page.read_text(), inline_code=True):
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m:
            s = slug(m[1])
            n = seen.get(s, 0)
            seen[s] = n + 1
            found.add(s if n == 0 else f"{s}-{n}")
    return found


def broken_links(page: Path) -> list[str]:
    """Each relative link or picture of ``page`` that does not resolve, as
    'TARGET: why'."""
    bad = []
    for line in _prose(page.read_text()):
        for target in LINK.findall(line):
            if EXTERNAL.match(target):
                continue
            path, _, anchor = target.partition("#")
            dest = (page.parent / path).resolve() if path else page
            if not dest.exists():
                bad.append(f"{target}: no file {dest}")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                bad.append(f"{target}: no heading #{anchor} in {dest.name}")
    return bad


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_resolves(page):
    assert broken_links(page) == []


def test_pages_link_their_pictures():
    """The pages do link pictures and anchors, so the test above has something to test."""
    text = "\n".join(p.read_text() for p in PAGES)
    assert len(re.findall(r"!\[[^\]]*\]\((?!https?:)[^)]+\.png\)", text)) >= 5
    assert re.search(r"\]\([^)#\s]+\.md#[\w-]+\)", text)


def test_a_broken_link_is_found(tmp_path):
    (tmp_path / "there.png").write_bytes(b"")
    (tmp_path / "other.md").write_text("# Other page\n\n## The `check`, step 2\n")
    page = tmp_path / "page.md"
    page.write_text(
        "# Page\n\n![ok](there.png) [ok](other.md#the-check-step-2) [ok](#page)\n"
        "[gone](missing.md) ![gone](gone.png) [no anchor](other.md#nowhere) "
        "[here](#nowhere-here) [web](https://example.org/x.md)\n\n"
        "    [in a code block](not-checked.md)\n\n`[inline code](not-checked.md)`\n")
    bad = broken_links(page)
    assert [b.split(":")[0] for b in bad] == ["missing.md", "gone.png",
                                              "other.md#nowhere", "#nowhere-here"], bad
