"""The scaffold shared by the small self-contained pages (audit history, fleet report).

A page is one HTML file that opens offline: the CSS is inline and every plot is a
base64 PNG ``data:`` URI, so nothing is fetched from a URL.  Callers escape every text
taken from logs or the state themselves (:func:`html.escape`).
"""

from __future__ import annotations

import base64
import html
from collections.abc import Iterable

#: the look the audit-history and fleet pages share; each page adds its column alignment
BASE_CSS = (
    "body{font-family:sans-serif;margin:1.5em}table{border-collapse:collapse}"
    "td,th{border:1px solid #bbb;padding:2px 6px;text-align:right}"
)

PAGE_END = "</body></html>\n"

#: what the browser may load: inline style and data: images only, no script, no URL
#: (the same policy as the analysis report)
CSP = "default-src 'none'; img-src data:; style-src 'unsafe-inline'; base-uri 'none'; form-action 'none'"


def data_uri(png: bytes) -> str:
    """``data:image/png;base64,…`` for PNG bytes (the page stays offline)."""
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def img_tag(png: bytes, alt_html: str) -> str:
    """An ``<img>`` of the PNG inlined as a data URI; ``alt_html`` is already escaped."""
    return f"<img alt='{alt_html}' src='{data_uri(png)}'>"


def page_head(title: str, css: str = "") -> str:
    """Doctype, head with the title and inline style (``BASE_CSS`` + ``css``), and the h1."""
    t = html.escape(title)
    return (
        f"<!doctype html><html><head><meta charset='utf-8'>"
        f"<meta http-equiv='Content-Security-Policy' content=\"{CSP}\"><title>{t}</title>\n"
        f"<style>{BASE_CSS}{css}</style></head><body>\n<h1>{t}</h1>"
    )


def consequences_html(under: Iterable[tuple[str, str]]) -> str:
    """The findings a finding caused, (check, message) each, as a list under its message
    ('' without any; the messages name their source)."""
    items = "".join(
        f"<li>consequence: [{html.escape(check)}] {html.escape(message)}</li>"
        for check, message in under
    )
    return f"<ul class='consequences'>{items}</ul>" if items else ""
