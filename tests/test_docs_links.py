"""The user documentation holds together: the README is a short front door, and every relative link and
``#anchor`` in README.md, CHANGELOG.md and docs/*.md leads somewhere (a file that exists, a heading that
exists, with the anchors GitHub gives headings)."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
#: The README is the front door: the two commands, running your videos, the options, the CSV columns, the
#: labels format, the library and the models; the rest lives in docs/ and CHANGELOG.md.
README_MAX_LINES = 300

DOCS = sorted([REPO / "README.md", REPO / "CHANGELOG.md", *(REPO / "docs").glob("*.md")])
# [text](target) and ![alt](target); the target ends at the first space (a title may follow) or ")"
_INLINE_LINK = re.compile(r"!?\[(?:[^\]\[]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_REFERENCE_LINK = re.compile(r"^\s{0,3}\[[^\]]+\]:\s+<?(\S+?)>?(?:\s|$)")
_EXTERNAL = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")  # http:, https:, mailto:, ...


def _prose_lines(text: str, blank_code_spans: bool = True) -> list[str]:
    """The lines of a Markdown text outside fenced code blocks (```), code spans blanked out unless told."""
    lines, fence = [], None
    for line in text.splitlines():
        stripped = line.lstrip()
        if fence is None and stripped.startswith(("```", "~~~")):
            fence = stripped[:3]
        elif fence is not None and stripped.startswith(fence):
            fence = None
        elif fence is None:
            lines.append(re.sub(r"`[^`]*`", "``", line) if blank_code_spans else line)
    return lines


def github_slug(heading: str) -> str:
    """The anchor GitHub gives a heading: its text lower-cased, punctuation other than ``-`` and ``_``
    removed, each space a ``-`` (inline code, links and emphasis as their text)."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link: its text
    text = text.replace("`", "").replace("*", "").strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """Every ``#anchor`` of a Markdown file: its headings' slugs, repeated ones numbered ``-1``, ``-2``, ..."""
    seen: dict[str, int] = {}
    found = set()
    for line in _prose_lines(path.read_text(encoding="utf-8"), blank_code_spans=False):
        m = re.match(r"^#{1,6}\s+(.+?)\s*#*\s*$", line)
        if not m:
            continue
        slug = github_slug(m.group(1))
        found.add(slug if slug not in seen else f"{slug}-{seen[slug]}")
        seen[slug] = seen.get(slug, 0) + 1
    return found


def relative_links(path: Path) -> list[str]:
    """The link targets of a Markdown file that point inside the repository (no scheme), code left out."""
    targets = []
    for line in _prose_lines(path.read_text(encoding="utf-8")):
        targets += _INLINE_LINK.findall(line)
        m = _REFERENCE_LINK.match(line)
        if m:
            targets.append(m.group(1))
    return [t for t in targets if not _EXTERNAL.match(t)]


def broken_links(path: Path) -> list[str]:
    """The relative links of ``path`` whose file, or whose ``#anchor`` in a Markdown file, does not exist."""
    broken = []
    for target in relative_links(path):
        file_part, _, anchor = target.partition("#")
        dest = (path.parent / file_part).resolve() if file_part else path
        if not dest.exists():
            broken.append(f"{target}: no such file")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            broken.append(f"{target}: no heading with this anchor in {dest.name}")
    return broken


def test_the_slugs_follow_github():
    assert github_slug("Live streams: cameras and stream URLs") == "live-streams-cameras-and-stream-urls"
    assert github_slug("SDNF - reconstruction") == "sdnf---reconstruction"
    assert github_slug("The `labels.csv` format") == "the-labelscsv-format"
    assert github_slug("Basic selectivity (paper Table I)") == "basic-selectivity-paper-table-i"
    assert github_slug("`n_ts` and [the paper](x.md)") == "n_ts-and-the-paper"


def test_a_broken_link_or_anchor_is_found(tmp_path):
    (tmp_path / "other.md").write_text("# Other page\n\n## Part two\n\n## Part two\n\n## The `x_y` option\n")
    page = tmp_path / "page.md"
    page.write_text("# Page\n\n[ok](other.md#part-two) [ok](other.md#part-two-1) [ok](other.md#the-x_y-option)\n"
                    "[ok](#page) `[in a code span](not-checked.md)`\n"
                    "[gone](missing.md) [bad anchor](other.md#part-three) [bad](#nowhere)\n"
                    "```\n[in code](not-checked.md)\n```\n[web](https://example.org/x.md)\n")
    assert broken_links(page) == ["missing.md: no such file",
                                  "other.md#part-three: no heading with this anchor in other.md",
                                  "#nowhere: no heading with this anchor in page.md"]


def test_the_readme_is_at_most_300_lines():
    lines = (REPO / "README.md").read_text(encoding="utf-8").count("\n")
    assert lines <= README_MAX_LINES, f"README.md has {lines} lines; move reference material to docs/"


@pytest.mark.parametrize("page", DOCS, ids=[str(p.relative_to(REPO)) for p in DOCS])
def test_every_relative_link_and_anchor_resolves(page):
    assert page.exists(), f"{page.relative_to(REPO)} is missing"
    assert broken_links(page) == []


def test_the_readme_links_the_guides_it_moved_out():
    targets = {t.partition("#")[0] for t in relative_links(REPO / "README.md")}
    assert {"docs/LIVE.md", "docs/EVENTS.md", "docs/CLI.md", "CHANGELOG.md"} <= targets
