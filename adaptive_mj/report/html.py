"""report.md -> report.html: one self-contained file a browser opens, with the same text.

The studies (bench, stress, sweep) write their report as Markdown; `write_html` converts that
Markdown, so both files say the same thing from one source. The figures it links (PNG, GIF, SVG,
JPEG beside the report) are embedded as base64 data URIs, the tables are sortable (click a column's
head; a small inline script, no network), and nothing outside the file is loaded.

The converter reads the Markdown subset the reports are written in (no dependency for it):
headings (#..######), paragraphs, fenced code blocks, pipe tables (with <br> in cells), "- " lists,
and inline `code`, **bold**, *italic*, [links](url) and ![images](path). Everything else is text,
HTML-escaped.
"""
from __future__ import annotations

import base64
import html
import re
from pathlib import Path

MIME = {".png": "image/png", ".gif": "image/gif", ".svg": "image/svg+xml", ".jpg": "image/jpeg",
        ".jpeg": "image/jpeg"}

_FENCE = re.compile(r"^```")
_HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")
_TABLE_RULE = re.compile(r"^\|?\s*:?-{3,}:?\s*(\|\s*:?-{3,}:?\s*)*\|?\s*$")
_LIST_ITEM = re.compile(r"^[-*]\s+(.*)$")
_IMAGE = re.compile(r"!\[([^\]]*)\]\(([^)\s]+)\)")
_LINK = re.compile(r"\[([^\]]+)\]\(([^)\s]+)\)")
_BOLD = re.compile(r"\*\*(?=\S)(.+?)(?<=\S)\*\*")
_ITALIC = re.compile(r"(?<![\w*\\])\*(?=\S)([^*\n]+?)(?<=\S)\*(?![\w*])")
_CODE = re.compile(r"`([^`\n]+)`")
_PLACEHOLDER = "\x00{}\x00"

STYLE = """
body { font: 15px/1.5 system-ui, -apple-system, "Segoe UI", sans-serif; color: #1d2330; background: #fff;
       max-width: 1100px; margin: 0 auto; padding: 1.5em 2em 4em; }
h1 { font-size: 1.7em; border-bottom: 2px solid #d0d7e2; padding-bottom: .3em; }
h2 { font-size: 1.3em; margin-top: 2em; border-bottom: 1px solid #e3e8ef; padding-bottom: .2em; }
h3 { font-size: 1.1em; }
code { font: 0.9em ui-monospace, "DejaVu Sans Mono", monospace; background: #f2f4f8; padding: 0 .25em;
       border-radius: 3px; }
pre { background: #f6f8fa; border: 1px solid #e3e8ef; padding: .8em 1em; overflow-x: auto; line-height: 1.35; }
pre code { background: none; padding: 0; font-size: 0.82em; }
table { border-collapse: collapse; margin: 1em 0; font-size: 0.9em; display: block; overflow-x: auto; }
th, td { border: 1px solid #d0d7e2; padding: .3em .6em; text-align: left; vertical-align: top; }
th { background: #eef2f7; cursor: pointer; user-select: none; white-space: nowrap; }
th[aria-sort=ascending]::after { content: " \\25B2"; font-size: .75em; }
th[aria-sort=descending]::after { content: " \\25BC"; font-size: .75em; }
tr:nth-child(even) td { background: #fafbfd; }
figure { margin: 1em 0; }
img { max-width: 100%; height: auto; border: 1px solid #e3e8ef; }
nav { background: #f6f8fa; border: 1px solid #e3e8ef; padding: .5em 1.2em; font-size: .92em; }
nav ul { margin: .3em 0; padding-left: 1.2em; }
.missing { color: #a33; font-style: italic; }
"""

# Click a column's head to sort the table by it (numbers by value, the rest as text); again to reverse.
SCRIPT = """
document.querySelectorAll("table.sortable").forEach(function (table) {
  var heads = table.querySelectorAll("thead th");
  heads.forEach(function (th, col) {
    th.title = "sort by this column";
    th.addEventListener("click", function () {
      var asc = th.getAttribute("aria-sort") !== "ascending";
      heads.forEach(function (h) { h.removeAttribute("aria-sort"); });
      th.setAttribute("aria-sort", asc ? "ascending" : "descending");
      var body = table.tBodies[0];
      var rows = Array.prototype.slice.call(body.rows);
      function key(row) {
        var text = row.cells[col] ? row.cells[col].textContent.trim() : "";
        var num = parseFloat(text.replace(/\\u2212/g, "-"));
        return isNaN(num) ? {n: null, s: text} : {n: num, s: text};
      }
      rows.sort(function (a, b) {
        var x = key(a), y = key(b), c;
        if (x.n !== null && y.n !== null) { c = x.n - y.n; }
        else if (x.n !== null) { c = -1; } else if (y.n !== null) { c = 1; }
        else { c = x.s.localeCompare(y.s); }
        return asc ? c : -c;
      });
      rows.forEach(function (r) { body.appendChild(r); });
    });
  });
});
"""


def data_uri(path: Path) -> str | None:
    """The file as a data: URI (None when it is missing or not an image type we embed)."""
    mime = MIME.get(path.suffix.lower())
    if mime is None or not path.is_file():
        return None
    return f"data:{mime};base64," + base64.b64encode(path.read_bytes()).decode("ascii")


def _slug(text: str, used: set[str]) -> str:
    base = re.sub(r"[^\w]+", "-", text.lower()).strip("-") or "section"
    slug, n = base, 2
    while slug in used:
        slug, n = f"{base}-{n}", n + 1
    used.add(slug)
    return slug


def inline(text: str, *, base: Path | None) -> str:
    """One line (or cell) of Markdown as HTML: code spans, images (embedded from `base`), links, bold,
    italic; <br> kept; everything else escaped."""
    kept: list[str] = []

    def keep(fragment: str) -> str:
        kept.append(fragment)
        return _PLACEHOLDER.format(len(kept) - 1)

    text = _CODE.sub(lambda m: keep(f"<code>{html.escape(m.group(1))}</code>"), text)

    def image(m: re.Match) -> str:
        alt, src = m.group(1), m.group(2)
        uri = data_uri(base / src) if base is not None and "://" not in src else None
        if uri is None:  # a missing figure is said in the text, not left as a broken link
            return keep(f'<span class="missing">[figure {html.escape(alt)}: {html.escape(src)} not found]</span>')
        return keep(f'<img alt="{html.escape(alt)}" src="{uri}">')

    text = _IMAGE.sub(image, text)
    text = _LINK.sub(lambda m: keep(f'<a href="{html.escape(m.group(2))}">{inline(m.group(1), base=base)}</a>'),
                     text)
    text = html.escape(text, quote=False).replace("&lt;br&gt;", "<br>").replace("\\|", "|")
    text = _BOLD.sub(r"<strong>\1</strong>", text)
    text = _ITALIC.sub(r"<em>\1</em>", text)
    return re.sub("\x00(\\d+)\x00", lambda m: kept[int(m.group(1))], text)


def _cells(line: str) -> list[str]:
    line = line.strip()
    if line.startswith("|"):
        line = line[1:]
    if line.endswith("|") and not line.endswith("\\|"):
        line = line[:-1]
    return [c.strip() for c in re.split(r"(?<!\\)\|", line)]


def _table(lines: list[str], *, base: Path | None) -> str:
    head, body = _cells(lines[0]), [_cells(line) for line in lines[2:]]
    out = ['<table class="sortable">', "<thead><tr>"
           + "".join(f"<th>{inline(c, base=base)}</th>" for c in head) + "</tr></thead>", "<tbody>"]
    for row in body:
        row = (row + [""] * len(head))[:max(len(head), len(row))]
        out.append("<tr>" + "".join(f"<td>{inline(c, base=base)}</td>" for c in row) + "</tr>")
    out.append("</tbody></table>")
    return "\n".join(out)


def markdown_to_html(text: str, *, base: Path | None = None) -> tuple[str, str, list[tuple[int, str, str]]]:
    """The body's HTML, the title (the first heading's text) and the headings (level, id, text)."""
    lines = text.splitlines()
    out: list[str] = []
    headings: list[tuple[int, str, str]] = []
    used: set[str] = set()
    para: list[str] = []

    def flush() -> None:
        if para:
            only_image = len(para) == 1 and _IMAGE.fullmatch(para[0].strip())
            body = "\n".join(inline(p, base=base) for p in para)
            out.append(f"<figure>{body}</figure>" if only_image else f"<p>{body}</p>")
            para.clear()

    i = 0
    while i < len(lines):
        line = lines[i]
        if _FENCE.match(line):
            flush()
            j = i + 1
            while j < len(lines) and not _FENCE.match(lines[j]):
                j += 1
            out.append("<pre><code>" + html.escape("\n".join(lines[i + 1:j])) + "</code></pre>")
            i = j + 1
            continue
        m = _HEADING.match(line)
        if m:
            flush()
            level, title = len(m.group(1)), m.group(2)
            slug = _slug(title, used)
            headings.append((level, slug, title))
            out.append(f'<h{level} id="{slug}">{inline(title, base=base)}</h{level}>')
            i += 1
            continue
        if line.lstrip().startswith("|") and i + 1 < len(lines) and _TABLE_RULE.match(lines[i + 1].strip()):
            flush()
            j = i + 2
            while j < len(lines) and lines[j].lstrip().startswith("|"):
                j += 1
            out.append(_table(lines[i:j], base=base))
            i = j
            continue
        if _LIST_ITEM.match(line):
            flush()
            items: list[str] = []
            while i < len(lines) and (_LIST_ITEM.match(lines[i]) or (lines[i].startswith("  ") and items)):
                m2 = _LIST_ITEM.match(lines[i])
                if m2:
                    items.append(m2.group(1))
                else:
                    items[-1] += " " + lines[i].strip()
                i += 1
            out.append("<ul>" + "".join(f"<li>{inline(it, base=base)}</li>" for it in items) + "</ul>")
            continue
        if not line.strip():
            flush()
        else:
            para.append(line)
        i += 1
    flush()
    title = next((t for level, _, t in headings if level == 1), "adaptive-mj report")
    return "\n".join(out), title, headings


def render(text: str, *, base: Path | None = None) -> str:
    """A whole HTML document for the Markdown `text` (figures read relative to `base`)."""
    body, title, headings = markdown_to_html(text, base=base)
    sections = [(slug, t) for level, slug, t in headings if level == 2]
    nav = ""
    if len(sections) > 2:  # a contents list for the long reports (the bench's 14 sections)
        nav = ("<nav><strong>Contents</strong><ul>" + "".join(
            f'<li><a href="#{slug}">{inline(t, base=None)}</a></li>' for slug, t in sections) + "</ul></nav>")
    # the contents go after the first heading and its opening paragraphs, before the first section
    cut = body.find("<h2")
    if nav and cut >= 0:
        body = body[:cut] + nav + "\n" + body[cut:]
    plain_title = re.sub(r"<[^>]+>", "", inline(title, base=None))
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
            "<meta name=\"generator\" content=\"adaptive_mj.report.html from report.md\">\n"
            f"<title>{plain_title}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n{body}\n"
            f"<script>{SCRIPT}</script>\n</body>\n</html>\n")


def write_html(markdown_path: Path, html_path: Path | None = None) -> Path:
    """report.md -> report.html beside it (or `html_path`), its figures embedded; returns the path."""
    markdown_path = Path(markdown_path)
    html_path = Path(html_path) if html_path is not None else markdown_path.with_suffix(".html")
    text = markdown_path.read_text(encoding="utf-8")
    html_path.write_text(render(text, base=markdown_path.parent), encoding="utf-8")
    return html_path
