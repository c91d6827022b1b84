"""report.html: the sweep's report as one page, readable without a server.

The report is written once, as markdown (testbed.analysis.report.render); this turns that
text into HTML with the figures inlined (data: URIs), so the page can be mailed or opened
from a laptop's disk. It knows exactly the markdown the report uses: headings, paragraphs,
lists, pipe tables, images, **bold** and `code`; anything else passes through as text.
Each run's directory is linked from a table at the end (its paths picture, its result).

What the page takes from the sweep's files is text, never markup: every string is escaped
(element text and attribute values alike, run directory names in links percent-encoded
too), and strings from result.json reach the markdown as one line (testbed.files.resultfile).
The only pictures inlined are the report's own figures: an image line whose path is not
`figures/....png`, a regular PNG inside the sweep directory, is shown as its text.
"""

from __future__ import annotations

import base64
import html
import re
import urllib.parse
from pathlib import Path

from common import boundedfile
from common.jsonfile import write_atomic
from testbed.files.resultfile import RESULT_NAME
from testbed.view import served

_IMG = re.compile(r"^!\[([^\]]*)\]\(([^)]+)\)$")
# The report's own figures: figures/NAME.png or figures/paths/NAME.png, plain names only.
_OWN_FIGURE = re.compile(r"figures/(paths/)?[A-Za-z0-9][A-Za-z0-9._-]*\.png")
_BOLD = re.compile(r"\*\*(.+?)\*\*")
_CODE = re.compile(r"`([^`]+)`")
STYLE = """
body { font-family: sans-serif; max-width: 1100px; margin: 2em auto; line-height: 1.45;
       color: #222; padding: 0 1em; }
table { border-collapse: collapse; margin: 1em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.5em; text-align: left; }
th { background: #f2f2f2; }
img { max-width: 100%; border: 1px solid #eee; }
code { background: #f5f5f5; padding: 0 0.2em; }
h1, h2, h3 { color: #134; }
"""


def _inline(text: str) -> str:
    out = html.escape(text, quote=False)
    out = _CODE.sub(r"<code>\1</code>", out)
    return _BOLD.sub(r"<strong>\1</strong>", out)


def _image(alt: str, src: str, base: Path) -> str:
    """The report's own figure `src` inlined; anything else as the line's text."""
    found = served.in_run(base, src) if _OWN_FIGURE.fullmatch(src) else None
    if found is not None and served.is_png(found):
        try:
            data = boundedfile.read(found, served.MAX_FILE_BYTES)
        except boundedfile.Refused:
            data = None
        if data is not None:
            uri = "data:image/png;base64," + base64.b64encode(data).decode()
            return f'<p><img alt="{html.escape(alt)}" src="{uri}"></p>'
    return f"<p>{_inline(f'![{alt}]({src})')}</p>"


def _table(rows: list[str]) -> str:
    cells = [[c.strip() for c in r.strip().strip("|").split("|")] for r in rows]
    head, body = cells[0], [c for c in cells[2:]]
    out = ["<table>", "<tr>" + "".join(f"<th>{_inline(c)}</th>" for c in head) + "</tr>"]
    out += ["<tr>" + "".join(f"<td>{_inline(c)}</td>" for c in row) + "</tr>" for row in body]
    return "\n".join(out + ["</table>"])


def to_html(markdown: str, base: Path) -> str:
    """The HTML body for `markdown`; image paths are relative to `base`."""
    out: list[str] = []
    para: list[str] = []
    lines = markdown.splitlines()
    i = 0

    def flush() -> None:
        if para:
            out.append(f"<p>{_inline(' '.join(para))}</p>")
            para.clear()

    while i < len(lines):
        line = lines[i]
        if not line.strip():
            flush()
        elif line.startswith("#"):
            flush()
            level = len(line) - len(line.lstrip("#"))
            out.append(f"<h{level}>{_inline(line[level:].strip())}</h{level}>")
        elif img := _IMG.match(line.strip()):
            flush()
            alt, src = img.groups()
            out.append(_image(alt, src, base))
        elif line.startswith("|"):
            flush()
            rows = []
            while i < len(lines) and lines[i].startswith("|"):
                rows.append(lines[i])
                i += 1
            out.append(_table(rows))
            continue
        elif line.startswith("- "):
            flush()
            items = []
            while i < len(lines) and lines[i].startswith("- "):
                items.append(f"<li>{_inline(lines[i][2:])}</li>")
                i += 1
            out.append("<ul>\n" + "\n".join(items) + "\n</ul>")
            continue
        else:
            para.append(line.strip())
        i += 1
    flush()
    return "\n".join(out)


def _runs_table(sweep_dir: Path) -> str:
    runs = sorted(p.parent for p in sweep_dir.glob(f"runs/*/{RESULT_NAME}"))
    if not runs:
        return ""
    rows = []
    for r in runs:
        href = html.escape(urllib.parse.quote(f"runs/{r.name}"), quote=True)
        links = [f'<a href="{href}/{RESULT_NAME}">result</a>']
        if (r / "paths.png").is_file():
            links.append(f'<a href="{href}/paths.png">paths</a>')
        replay = f"<code>testbed view {html.escape(str(r))}</code>"
        rows.append(
            f"<tr><td>{html.escape(r.name)}</td><td>{' '.join(links)}</td><td>{replay}</td></tr>"
        )
    head = "<tr><th>run</th><th>files</th><th>replay in the browser</th></tr>"
    return "\n".join(["<h2>Runs</h2>", "<table>", head, *rows, "</table>"])


def write_html(sweep_dir: Path, markdown: str) -> Path:
    """Write DIR/report.html from the report's markdown; returns its path."""
    title = markdown.splitlines()[0].lstrip("# ").strip() if markdown else "Sweep report"
    page = "\n".join([
        "<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
        f"<title>{html.escape(title)}</title>", f"<style>{STYLE}</style>", "</head>",
        "<body>", to_html(markdown, sweep_dir), _runs_table(sweep_dir), "</body>", "</html>",
    ])  # fmt: skip
    path = sweep_dir / "report.html"
    write_atomic(path, page)  # a fresh temporary name beside it, never through a link
    return path
