"""HTML pieces of the report page: escaped text, tables, and figures carried inside the page.

A figure is carried by the page itself, never linked: an SVG file is inlined as ``<svg>``
(vector: sharp in print and at any browser zoom, its text searchable), a PNG as a base64
``data:`` URI. The page therefore opens alone, offline, in any browser, and can be mailed.
"""

from __future__ import annotations

import base64
import html
import re
from pathlib import Path
from typing import Any

_XML_PROLOGUE = re.compile(r"^\s*(<\?xml[^>]*>\s*)?(<!DOCTYPE[^>]*>\s*)?", re.IGNORECASE)


def esc(value: Any) -> str:
    """``value`` as text, HTML-escaped."""
    return html.escape(str(value))


def table(header: list[str], rows: list[list[str]], cls: str = "") -> str:
    """A table; header cells are escaped here, body cells are HTML already."""
    head = "".join(f"<th>{esc(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>" for row in rows)
    attr = f' class="{esc(cls)}"' if cls else ""
    return f"<table{attr}><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def facts(rows: list[tuple[str, str]]) -> str:
    """A two-column table of named facts (values are HTML already)."""
    body = "".join(f"<tr><th>{esc(k)}</th><td>{v}</td></tr>" for k, v in rows)
    return f'<table class="facts"><tbody>{body}</tbody></table>'


def embedded(path: Path) -> str:
    """The figure file ``path`` carried inside the page: an SVG file's markup (its XML
    prologue dropped, sized by CSS), a PNG as an ``<img>`` with a data URI."""
    if path.suffix == ".svg":
        text = _XML_PROLOGUE.sub("", path.read_text(encoding="utf-8"), count=1)
        return f'<div class="svg" role="img" aria-label="{esc(path.stem)}">{text}</div>'
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return f'<img src="data:image/png;base64,{data}" alt="{esc(path.name)}">'
