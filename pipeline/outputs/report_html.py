"""HTML pieces of ``report.html``: a self-contained page, tables, paragraphs.

Style and script are inline and images are base64 ``data:`` URIs: the page loads nothing else.
Text is escaped.
"""

from __future__ import annotations

import base64
import html
import math
from typing import Any

__all__ = ["img", "table", "para", "page"]

_CSS = (
    "body{font-family:sans-serif;max-width:1100px;margin:1em auto;color:#222}"
    "table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #bbb;padding:2px 8px;"
    "text-align:left}th{background:#eee}td.n{text-align:right}"
    "img{max-width:100%;display:block;margin:.5em 0}h2{border-bottom:2px solid #456;"
    "margin-top:1.5em}.note{color:#555;font-size:90%}"
)
# Sets body[data-images] to "ok" when every figure decoded (a browser test reads it).
_SCRIPT = (
    "window.addEventListener('load',function(){var i=Array.from(document.images);"
    "document.body.dataset.images=i.every(function(m){return m.complete&&m.naturalWidth>0})"
    "?'ok':'broken';});"
)


def img(png: bytes, alt: str) -> str:
    """An ``<img>`` holding ``png`` inline."""
    b64 = base64.b64encode(png).decode("ascii")
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{b64}">'


def table(header: list[str], rows: list[list[Any]]) -> str:
    """A table; numbers right-aligned (floats to 4 significant digits), None and NaN as a dash."""

    def cell(v):
        if v is None or (isinstance(v, float) and not math.isfinite(v)):
            return "<td class='n'>–</td>"
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            return f"<td>{html.escape(str(v))}</td>"
        return f"<td class='n'>{v:.4g}</td>" if isinstance(v, float) else f"<td class='n'>{v}</td>"

    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(cell(v) for v in r) + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def para(text: str) -> str:
    """A paragraph of escaped text."""
    return f"<p>{html.escape(text)}</p>"


def page(title: str, sections: list[str]) -> str:
    """The whole document: ``title`` and the sections' HTML in order."""
    t = html.escape(title)
    return (
        f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{t}</title>"
        f"<style>{_CSS}</style><script>{_SCRIPT}</script></head><body><h1>{t}</h1>"
        + "\n".join(sections)
        + "</body></html>\n"
    )
