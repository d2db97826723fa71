"""Docs build: render the docstrings' reStructuredText habits as Markdown for the API reference.

The docstrings are written in the Google style, with Sphinx roles for names (:class:`~a.b.C`, :func:`f`) and a few
reST simple tables (columns under ``====  ====`` borders). mkdocstrings renders Markdown and would print both
literally. This griffe extension (mkdocs.yml, ``extensions``) rewrites, in every loaded docstring:

* each role to the name in backticks, shortened to its last part when written with a leading ``~`` as Sphinx does;
* each simple table to a Markdown table (a row whose first cell is blank continues the row above).
"""

from __future__ import annotations

import re
from typing import Any

import griffe

ROLE = re.compile(r":(?:py:)?(?:class|func|meth|mod|attr|data|obj|exc|const):`(~?)([^`]+)`")
BORDER = re.compile(r"^(\s*)(=+)((?:\s+=+)+)\s*$")


def plain_roles(text: str) -> str:
    """The text with every Sphinx role replaced by its name as inline code."""
    return ROLE.sub(lambda m: f"`{m.group(2).rsplit('.', 1)[-1] if m.group(1) else m.group(2)}`", text)


def _cells(line: str, starts: list[int]) -> list[str]:
    """The line cut at the column starts, each cell stripped."""
    ends = [*starts[1:], None]
    return [line[a:b].strip() if b is not None else line[a:].strip() for a, b in zip(starts, ends, strict=True)]


def _escape_pipes(cell: str) -> str:
    """The cell with its pipes outside code spans escaped (the table extension leaves those inside alone)."""
    parts = re.split(r"(`+[^`]*`+)", cell)
    return "".join(part if part.startswith("`") else part.replace("|", "\\|") for part in parts)


def _markdown_table(block: list[str], starts: list[int]) -> list[str]:
    """A reST simple table (its lines without the borders, header first) as Markdown table lines."""
    rows: list[list[str]] = []
    for line in block:
        if not line.strip():
            continue
        cells = _cells(line, starts)
        if rows and not cells[0]:
            rows[-1] = [f"{a} {b}".strip() for a, b in zip(rows[-1], cells, strict=True)]
        else:
            rows.append(cells)
    out = ["| " + " | ".join(_escape_pipes(c) for c in row) + " |" for row in rows]
    return [out[0], "|" + "---|" * len(starts), *out[1:]] if out else []


def markdown_tables(text: str) -> str:
    """The text with every reST simple table (three borders: above, under the header, below) as a Markdown table."""
    lines = text.split("\n")
    out: list[str] = []
    i = 0
    while i < len(lines):
        match = BORDER.match(lines[i])
        borders = [j for j in range(i + 1, len(lines)) if lines[j].strip() == lines[i].strip()][:2] if match else []
        if len(borders) < 2:
            out.append(lines[i])
            i += 1
            continue
        starts = [m.start() for m in re.finditer(r"=+", lines[i])]
        header, body = lines[i + 1 : borders[0]], lines[borders[0] + 1 : borders[1]]
        out.extend(["", *_markdown_table(header + body, starts), ""])
        i = borders[1] + 1
    return "\n".join(out)


class RestToMarkdown(griffe.Extension):
    """Rewrites the roles and simple tables of every loaded object's docstring."""

    def on_object(self, *, obj: griffe.Object, loader: griffe.GriffeLoader, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = markdown_tables(plain_roles(obj.docstring.value))
