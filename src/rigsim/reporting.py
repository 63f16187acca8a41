"""Self-contained HTML pages from the procedures' Markdown reports.

Every procedure writes ``report.md`` next to its PNG plots; :func:`markdown_to_html` turns it into
``report.html`` with the images embedded as base64 data URIs. The page can then be mailed or
archived as one file. Markdown is parsed with markdown-it-py (CommonMark plus tables). A small
inline script marks ``<body data-images-ok="N/M">`` once the images have decoded; the
headless-Chromium test reads it.
"""

from __future__ import annotations

import base64
import html
import mimetypes
import re
from pathlib import Path

CSS = """
body { font-family: -apple-system, "Segoe UI", Roboto, "DejaVu Sans", sans-serif; max-width: 1200px;
       margin: 2em auto; padding: 0 1em; color: #1d1d1f; line-height: 1.45; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.92em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; }
th { background: #f2f2f2; }
td { font-variant-numeric: tabular-nums; }
pre { background: #f6f8fa; padding: 0.8em; overflow-x: auto; font-size: 0.85em; }
code { background: #f6f8fa; padding: 0 0.2em; }
img { max-width: 100%; border: 1px solid #ddd; margin: 0.4em 0; }
h1 { font-size: 1.6em; border-bottom: 2px solid #333; }
h2 { font-size: 1.25em; border-bottom: 1px solid #ccc; margin-top: 1.6em; }
"""

SCRIPT = """
window.addEventListener('load', function () {
  var imgs = document.images, ok = 0;
  for (var i = 0; i < imgs.length; i++) { if (imgs[i].complete && imgs[i].naturalWidth > 0) ok++; }
  document.body.setAttribute('data-images-ok', ok + '/' + imgs.length);
});
"""


def _data_uri(path: Path) -> str:
    mime = mimetypes.guess_type(path.name)[0] or "application/octet-stream"
    return f"data:{mime};base64," + base64.b64encode(path.read_bytes()).decode()


def markdown_to_html(md_path, html_path=None, *, title: str | None = None) -> Path:
    """Render ``md_path`` to a self-contained HTML file (images embedded). Returns its path."""
    from markdown_it import MarkdownIt

    md_path = Path(md_path)
    html_path = Path(html_path) if html_path else md_path.with_suffix(".html")
    text = md_path.read_text()
    body = MarkdownIt("commonmark", {"html": False}).enable("table").render(text)
    base = md_path.parent

    def embed(m: re.Match) -> str:
        src = html.unescape(m.group(2))
        p = (base / src)
        if src.startswith(("data:", "http:", "https:")) or not p.is_file():
            return m.group(0)
        return f'{m.group(1)}"{_data_uri(p)}"'

    body = re.sub(r'(<img [^>]*?src=)"([^"]+)"', embed, body)
    if title is None:
        m = re.search(r"^# (.+)$", text, re.M)
        title = m.group(1) if m else md_path.stem
    page = (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{html.escape(title)}</title>"
            f"<style>{CSS}</style><script>{SCRIPT}</script></head><body>\n{body}\n</body></html>\n")
    from rigsim.files.atomic import atomic_write_bytes

    return atomic_write_bytes(html_path, page.encode())


def _fmt_row(cells, widths):
    return "  ".join(str(c).rjust(w) if i else str(c).ljust(w) for i, (c, w) in enumerate(zip(cells, widths)))


def text_table(header, rows) -> str:
    """A plain-text table (first column left-aligned, the others right-aligned) for terminals."""
    widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(len(header))]
    out = [_fmt_row(header, widths), _fmt_row(["-" * w for w in widths], widths)]
    out += [_fmt_row(r, widths) for r in rows]
    return "\n".join(out)


def safe_text(s: str, limit: int = 200) -> str:
    """``s`` for a terminal: control characters escaped (\\x1b, \\n, …), at most ``limit`` characters."""
    from rigsim.files.names import printable

    return printable(s, limit)

