"""A single self-contained HTML report: headings, paragraphs, tables, embedded PNG images.

A person reads it in any browser without running Python and without any other file: images are
embedded as base64 ``data:`` URIs, the style is a short inline ``<style>`` block, there is no
JavaScript. All text (headings, paragraphs, table cells, captions) is escaped with
:func:`html.escape`, so names and messages from a user's files cannot inject markup.

Files are written atomically (:func:`spaceid_gym.log.write_bytes_atomic`: a temporary file in the target's directory,
then ``os.replace``), so a failure never leaves a partial report (or plot) behind and an existing file
is either kept or fully replaced.
"""

from __future__ import annotations

import base64
import html
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from spaceid_gym.errors import SpaceIdInputError
from spaceid_gym.files import write_bytes_atomic

PathLike = str | os.PathLike[str]

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

_STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; max-width: 1150px;
       margin: 2em auto; padding: 0 1em; color: #222; line-height: 1.45; }
h1 { border-bottom: 2px solid #446; padding-bottom: 0.2em; }
h2 { margin-top: 1.8em; border-bottom: 1px solid #ccd; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.92em; }
caption { caption-side: top; text-align: left; font-weight: 600; padding-bottom: 0.3em; }
th, td { border: 1px solid #bbc; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }
th { background: #eef; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
tr:nth-child(even) td { background: #f8f8fc; }
figure { margin: 1em 0; }
figure img { max-width: 100%; height: auto; border: 1px solid #ddd; }
figcaption { font-size: 0.9em; color: #444; }
pre { background: #f4f4f8; padding: 0.8em; overflow-x: auto; font-size: 0.88em; }
"""


def _format_cell(value: Any, float_format: str) -> tuple[str, bool]:
    """Escaped text of a table cell and whether it is numeric (right-aligned)."""
    if value is None:
        return "", False
    if isinstance(value, (bool, np.bool_)):
        return ("yes" if value else "no"), False
    if isinstance(value, (int, np.integer)):
        return str(int(value)), True
    if isinstance(value, (float, np.floating)):
        number = float(value)
        return (format(number, float_format) if math.isfinite(number) else str(number)), True
    if isinstance(value, (list, tuple, np.ndarray)):
        return html.escape(", ".join(_format_cell(v, float_format)[0] for v in np.asarray(value, dtype=object).ravel())), False
    return html.escape(str(value)), False


class HtmlReport:
    """Builds one self-contained HTML page, piece by piece, in the order of the calls.

    Example::

        report = HtmlReport("Diagnosis of run1")
        report.add_heading("Model vs measurement")
        report.add_image("overlay.png", caption="measured vs predicted base rate")
        report.add_table(analysis.channel_rows(), caption="per channel")
        report.write("run1/report.html")

    Args:
        title: page title and top heading.
        float_format: format spec of float table cells (default ``.4g``).
    """

    def __init__(self, title: str, float_format: str = ".4g") -> None:
        self.title = str(title)
        self.float_format = float_format
        self._parts: list[str] = []

    def add_heading(self, text: str, level: int = 2) -> None:
        """A section heading, ``<h2>`` by default (``level`` 2-6; the title is the only ``<h1>``)."""
        if level not in range(2, 7):
            raise SpaceIdInputError(f"HtmlReport.add_heading: level must be 2..6, got {level!r}")
        self._parts.append(f"<h{level}>{html.escape(str(text))}</h{level}>")

    def add_paragraph(self, text: str) -> None:
        """A paragraph of plain text (escaped; blank lines are not interpreted)."""
        self._parts.append(f"<p>{html.escape(str(text))}</p>")

    def add_preformatted(self, text: str) -> None:
        """Monospaced text kept as is (escaped), e.g. a command line or a JSON excerpt."""
        self._parts.append(f"<pre>{html.escape(str(text))}</pre>")

    def add_table(
        self,
        rows: Sequence[Mapping[str, Any]] | Sequence[Sequence[Any]],
        caption: str = "",
        header: Sequence[str] | None = None,
    ) -> None:
        """A table from a list of dicts (columns: keys in order of first appearance; missing cells empty)
        or from ``header`` plus a list of row sequences. Floats use ``float_format``, booleans yes/no."""
        rows = list(rows)
        if rows and all(isinstance(row, Mapping) for row in rows):
            columns = list(header) if header is not None else list(dict.fromkeys(key for row in rows for key in row))
            cells = [[row.get(column) for column in columns] for row in rows]  # type: ignore[union-attr]
        elif header is not None and all(not isinstance(row, (Mapping, str)) for row in rows):
            columns = list(header)
            cells = [list(row) for row in rows]  # type: ignore[arg-type]
            for i, row in enumerate(cells):
                if len(row) != len(columns):
                    raise SpaceIdInputError(f"HtmlReport.add_table: row {i} has {len(row)} cells, the header has {len(columns)}")
        else:
            raise SpaceIdInputError("HtmlReport.add_table: expected a list of dicts, or header= plus a list of row sequences")
        lines = ["<table>"]
        if caption:
            lines.append(f"<caption>{html.escape(str(caption))}</caption>")
        lines.append("<tr>" + "".join(f"<th>{html.escape(str(column))}</th>" for column in columns) + "</tr>")
        for row in cells:
            formatted = [_format_cell(value, self.float_format) for value in row]
            lines.append(
                "<tr>" + "".join(f'<td class="num">{t}</td>' if num else f"<td>{t}</td>" for t, num in formatted) + "</tr>"
            )
        lines.append("</table>")
        self._parts.append("\n".join(lines))

    def add_image(self, image: PathLike | bytes, caption: str = "", alt: str | None = None) -> None:
        """A PNG image (file path or the PNG bytes), embedded as a base64 data URI, with a caption."""
        if isinstance(image, (bytes, bytearray)):
            data, source = bytes(image), "the image bytes"
        else:
            path = Path(image)
            if not path.is_file():
                raise SpaceIdInputError(f"HtmlReport.add_image: {path}: no such image file")
            data, source = path.read_bytes(), str(path)
        if not data.startswith(_PNG_SIGNATURE):
            raise SpaceIdInputError(
                f"HtmlReport.add_image: {source}: expected a PNG image (it does not start with the PNG signature)"
            )
        uri = "data:image/png;base64," + base64.b64encode(data).decode("ascii")
        alt_text = html.escape(str(alt if alt is not None else caption), quote=True)
        figure = f'<figure><img src="{uri}" alt="{alt_text}">'
        if caption:
            figure += f"<figcaption>{html.escape(str(caption))}</figcaption>"
        self._parts.append(figure + "</figure>")

    def to_html(self) -> str:
        """The whole page as a string."""
        title = html.escape(self.title)
        body = "\n".join(self._parts)
        return (
            '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">\n<title>{title}</title>\n'
            f"<style>{_STYLE}</style>\n</head>\n<body>\n<h1>{title}</h1>\n{body}\n</body>\n</html>\n"
        )

    def write(self, path: PathLike) -> Path:
        """Write the page to ``path`` (UTF-8) atomically; returns the path."""
        return write_bytes_atomic(path, self.to_html().encode("utf-8"))
