"""A report as a format-neutral tree of blocks, rendered to Markdown and to a self-contained HTML page.

Every report that writes both a ``.md`` and an ``.html`` file builds one list of blocks and
renders it twice, so the two documents always say the same thing and no report parses its own
Markdown back. The blocks know nothing of robots or blades; the renderers know nothing of
what a report states.
"""

from __future__ import annotations

import base64
import html
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "Block",
    "BulletList",
    "Figure",
    "Heading",
    "Paragraph",
    "Preformatted",
    "Table",
    "render_html",
    "render_markdown",
    "table",
]


@dataclass(frozen=True)
class Heading:
    """A heading of `level` 1-6."""

    level: int
    text: str


@dataclass(frozen=True)
class Paragraph:
    """One paragraph of running text."""

    text: str


@dataclass(frozen=True)
class BulletList:
    """An unordered list, one line per item."""

    items: tuple[str, ...]


@dataclass(frozen=True)
class Table:
    """A table: header cells and rows of cells (text; numbers right-aligned in HTML)."""

    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]


@dataclass(frozen=True)
class Figure:
    """An image file beside the document, with its caption.

    `caption_below` adds the caption as an italic line under the image in Markdown (HTML always
    shows it as the figure's caption).
    """

    file: str
    caption: str
    caption_below: bool = True


@dataclass(frozen=True)
class Preformatted:
    """Text shown as typed, in a fixed-width font (a console table)."""

    text: str


Block = Heading | Paragraph | BulletList | Table | Figure | Preformatted


def table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> Table:
    """A :class:`Table` from any sequences of cells."""
    return Table(tuple(header), tuple(tuple(r) for r in rows))


def _markdown_block(b: Block) -> str:
    if isinstance(b, Heading):
        return "#" * b.level + " " + b.text
    if isinstance(b, Paragraph):
        return b.text
    if isinstance(b, BulletList):
        return "\n".join(f"- {item}" for item in b.items)
    if isinstance(b, Table):
        lines = [
            "| " + " | ".join(b.header) + " |",
            "|" + "|".join("---" for _ in b.header) + "|",
        ]
        lines.extend("| " + " | ".join(c.replace("|", "\\|") for c in row) + " |" for row in b.rows)
        return "\n".join(lines)
    if isinstance(b, Preformatted):
        return "```\n" + b.text + "\n```"
    image = f"![{b.caption}]({b.file})"
    return f"{image}\n\n*{b.caption}*" if b.caption_below else image


def render_markdown(blocks: Sequence[Block]) -> str:
    """The blocks as Markdown, separated by blank lines, ending with a newline."""
    return "\n\n".join(_markdown_block(b) for b in blocks) + "\n"


CSS = (
    "body{font-family:sans-serif;max-width:70em;margin:2em auto;padding:0 1em;color:#222}"
    "table{border-collapse:collapse;margin:1em 0}"
    "th,td{border:1px solid #aaa;padding:.25em .6em;text-align:right;vertical-align:top}"
    "th:first-child,td:first-child,td.text{text-align:left}th{background:#eee}"
    "img{max-width:100%}figure{margin:1em 0}figcaption{font-style:italic}"
)
"""Style of every HTML report."""

_PRE_CSS = "pre{background:#f6f6f6;padding:.5em;overflow-x:auto}"
"""Style added to a page that holds :class:`Preformatted` blocks."""

_NUMERIC = re.compile(r"^[\s(]*[-+−]?[0-9.]+([eE][-+]?[0-9]+)?([\s,/]+[-+−]?[0-9.]+)*[)\s]*[a-zµ%°]*$")


def _html_cell(text: str) -> str:
    """A table cell: numbers right-aligned (the CSS default), text such as descriptions left."""
    style = "" if _NUMERIC.match(text) else ' class="text"'
    return f"<td{style}>{html.escape(text)}</td>"


def _html_block(b: Block, directory: Path, embed: bool) -> str:
    e = html.escape
    if isinstance(b, Heading):
        return f"<h{b.level}>{e(b.text)}</h{b.level}>"
    if isinstance(b, Paragraph):
        return f"<p>{e(b.text)}</p>"
    if isinstance(b, BulletList):
        return "<ul>" + "".join(f"<li>{e(i)}</li>" for i in b.items) + "</ul>"
    if isinstance(b, Table):
        head = "".join(f"<th>{e(h)}</th>" for h in b.header)
        body = "".join("<tr>" + "".join(_html_cell(c) for c in row) + "</tr>" for row in b.rows)
        return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
    if isinstance(b, Preformatted):
        return f"<pre>{e(b.text)}</pre>"
    src = b.file
    if embed:
        data = base64.b64encode((directory / b.file).read_bytes()).decode("ascii")
        src = f"data:image/png;base64,{data}"
    return f'<figure><img src="{e(src)}" alt="{e(b.caption)}"><figcaption>{e(b.caption)}</figcaption></figure>'


def render_html(blocks: Sequence[Block], title: str, directory: Path, *, embed: bool = True) -> str:
    """The blocks as one HTML page; figures read from `directory` and embedded as data URIs
    when `embed` (a self-contained page), else linked by file name."""
    style = CSS + (_PRE_CSS if any(isinstance(b, Preformatted) for b in blocks) else "")
    out = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{html.escape(title)}</title><style>{style}</style></head><body>",
    ]
    out.extend(_html_block(b, directory, embed) for b in blocks)
    out.append("</body></html>")
    return "\n".join(out) + "\n"
