"""A self-contained HTML report page: headings, paragraphs, tables and figures.

Every image is embedded as a base64 ``data:`` URI and the page has no script
and no external reference, so it opens offline from a single file.
"""
from __future__ import annotations

import base64
import html
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

from ..atomic import atomic_write_text

CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,Helvetica,Arial,sans-serif;margin:2em auto;
max-width:1200px;padding:0 1em;color:#222;line-height:1.4}
h1{font-size:1.6em}h2{font-size:1.3em;border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:1.6em}
h3{font-size:1.1em}
table{border-collapse:collapse;margin:.6em 0 1em;font-size:.9em}
th,td{border:1px solid #bbb;padding:.25em .55em;text-align:left;vertical-align:top}
th{background:#eef2f7}tr:nth-child(even) td{background:#fafafa}
td.num{text-align:right;font-variant-numeric:tabular-nums}
.note{background:#fff6d6;border-left:4px solid #e0b100;padding:.4em .8em;margin:.6em 0}
figure{margin:1em 0}figure img{max-width:100%;border:1px solid #ddd}
figcaption{font-size:.9em;color:#555}
.grid{display:flex;flex-wrap:wrap;gap:1em}.grid figure{flex:1 1 520px}
code{background:#f3f3f3;padding:0 .2em}
"""


@dataclass
class Page:
    """An HTML page built piece by piece (each method appends; :meth:`render` gives the text)."""

    title: str
    parts: list[str] = field(default_factory=list)
    n_tables: int = 0

    def heading(self, text: str, level: int = 2) -> None:
        self.parts.append(f"<h{level}>{html.escape(text)}</h{level}>")

    def paragraph(self, text: str, note: bool = False) -> None:
        cls = ' class="note"' if note else ""
        self.parts.append(f"<p{cls}>{html.escape(text)}</p>")

    def bullets(self, items: Sequence[str]) -> None:
        self.parts.append("<ul>" + "".join(f"<li>{html.escape(i)}</li>" for i in items) + "</ul>")

    def table(self, header: Sequence[str], rows: Sequence[Sequence[Any]], caption: str | None = None) -> None:
        """A table; numbers are right-aligned."""
        self.n_tables += 1
        out = [f'<table id="table{self.n_tables}">']
        if caption:
            out.append(f"<caption>{html.escape(caption)}</caption>")
        out.append("<thead><tr>" + "".join(f"<th>{html.escape(str(h))}</th>" for h in header) + "</tr></thead>")
        out.append("<tbody>")
        for r in rows:
            cells = []
            for v in r:
                s = "" if v is None else str(v)
                num = _is_num(s)
                cells.append(f'<td{" class=num" if num else ""}>{html.escape(s)}</td>')
            out.append("<tr>" + "".join(cells) + "</tr>")
        out.append("</tbody></table>")
        self.parts.append("".join(out))

    def image(self, png: str | Path | bytes, caption: str = "") -> None:
        """Embed a PNG (path or bytes) as a data URI; a missing file is skipped."""
        if not isinstance(png, bytes):
            p = Path(png)
            if not p.is_file():
                return
            png = p.read_bytes()
        b64 = base64.b64encode(png).decode("ascii")
        alt = html.escape(caption or "figure")
        cap = f"<figcaption>{html.escape(caption)}</figcaption>" if caption else ""
        self.parts.append(f'<figure><img alt="{alt}" src="data:image/png;base64,{b64}">{cap}</figure>')

    def images(self, items: Sequence[tuple[Path, str]]) -> None:
        """Several figures side by side (wrapping)."""
        self.parts.append('<div class="grid">')
        for p, cap in items:
            self.image(p, cap)
        self.parts.append("</div>")

    def render(self) -> str:
        body = "\n".join(self.parts)
        return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
                f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
                f"<title>{html.escape(self.title)}</title><style>{CSS}</style></head>\n"
                f"<body><h1>{html.escape(self.title)}</h1>\n{body}\n</body></html>\n")

    def write(self, path: str | Path) -> Path:
        atomic_write_text(path, self.render())
        return Path(path)


def _is_num(s: str) -> bool:
    t = s.strip().rstrip("%").replace(" ms", "")
    if not t:
        return False
    try:
        float(t)
        return True
    except ValueError:
        return False


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> list[str]:
    """The same table as Markdown lines."""
    lines = ["| " + " | ".join(str(h) for h in header) + " |", "|" + "---|" * len(header)]
    for r in rows:
        lines.append("| " + " | ".join("" if v is None else str(v) for v in r) + " |")
    return lines


def add_markdown(page: Page, md: str) -> None:
    """Append the Markdown that cdnf_ti writes (headings, bullet lists, pipe tables, paragraphs) to ``page``.

    Only that subset is understood; the top-level ``#`` heading is skipped (the page has its title).
    """
    lines = md.splitlines()
    i = 0
    bullets: list[str] = []

    def flush() -> None:
        if bullets:
            page.bullets([b.replace("`", "") for b in bullets])
            bullets.clear()

    while i < len(lines):
        ln = lines[i].rstrip()
        if ln.startswith("|"):
            flush()
            block = []
            while i < len(lines) and lines[i].startswith("|"):
                block.append(lines[i].strip())
                i += 1
            block = [row for row in block if not set(row) <= set("|-: ")]  # the |---|---| rule
            cells = [[c.strip().replace("`", "") for c in row[1:-1].split(" | ")] for row in block]
            body = cells[1:]
            page.table(cells[0], body)
            continue
        if ln.startswith("#"):
            flush()
            level = len(ln) - len(ln.lstrip("#"))
            if level > 1:
                page.heading(ln.lstrip("#").strip().replace("`", ""), min(level, 4))
        elif ln.startswith("- "):
            bullets.append(ln[2:])
        elif ln.strip():
            flush()
            page.paragraph(ln.replace("`", ""))
        else:
            flush()
        i += 1
    flush()
