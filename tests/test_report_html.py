"""report.html: the studies' Markdown report as one self-contained HTML file with the same text,
its figures embedded, its tables sortable; opened in headless Chromium (tests/headless_chromium.py,
the DevTools protocol over a pipe), which must show a page that is not blank, load nothing from
outside the file and log no error."""
import base64
import html as html_lib
import io
import re
from pathlib import Path

import numpy as np
import pytest

from adaptive_mj.report.html import markdown_to_html, render, write_html
from headless_chromium import Browser, find_browser

NO_BROWSER = ("Chromium is not installed (Debian's `chromium` package; .ci/run installs it when it runs as root "
              "with apt-get)")


def text_of_html(doc: str) -> str:
    """The words a reader sees: the body without scripts, styles and the contents list, tags removed."""
    body = doc.split("<body>", 1)[1]
    body = re.sub(r"<(script|style|nav)\b.*?</\1>", " ", body, flags=re.S)
    return html_lib.unescape(re.sub(r"<[^>]+>", " ", body))


def text_of_markdown(md: str) -> str:
    """The words of the Markdown: images and link targets dropped, markup characters left to the tokenizer."""
    md = re.sub(r"!\[[^\]]*\]\([^)]*\)", " ", md)
    md = re.sub(r"\]\([^)]*\)", "] ", md)
    return md.replace("<br>", " ").replace("\\|", "|")


def words(text: str) -> list[str]:
    return re.findall(r"\w+", text)


def png(path: Path, *, seed: int = 0) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4, 2.5))
    ax.plot(np.random.default_rng(seed).standard_normal(50).cumsum())
    ax.set_ylabel("error [m]")
    fig.savefig(path, dpi=60)
    plt.close(fig)
    return path


REPORT = """# A report with *every* piece

Intro with `code`, **bold**, a [link](https://example.org) and a < sign & an ampersand.

| run | error [m] | note |
|---|---|---|
| b | 10 | ten<br>second line |
| a | 2.5 | a \\| pipe |
| c | -1e-3 | <script>alert(1)</script> |

## Figures

![curve](figures/curve.png)

![missing one](figures/nope.png)

```
fixed   width
  text  <kept>
```

- first item
- second item

## Last section

Closing words.
"""


@pytest.fixture
def report(tmp_path) -> Path:
    (tmp_path / "figures").mkdir()
    png(tmp_path / "figures" / "curve.png")
    path = tmp_path / "report.md"
    path.write_text(REPORT)
    return path


def test_markdown_becomes_html_with_the_same_words_and_embedded_figures(report):
    out = write_html(report)
    doc = out.read_text()
    assert out == report.with_suffix(".html")
    missing = '<span class="missing">[figure missing one: figures/nope.png not found]</span>'
    assert words(text_of_html(doc.replace(missing, ""))) == words(text_of_markdown(REPORT))
    figure = base64.b64encode((report.parent / "figures" / "curve.png").read_bytes()).decode()
    assert f'src="data:image/png;base64,{figure}"' in doc
    assert missing in doc  # a figure that is not there is said, not left as a broken image
    assert re.findall(r'\ssrc="(?!data:)', doc) == []  # nothing is loaded from outside the file
    assert "<script>alert(1)</script>" not in doc and "&lt;script&gt;alert(1)&lt;/script&gt;" in doc
    assert "<td>ten<br>second line</td>" in doc and "<td>a | pipe</td>" in doc
    assert '<table class="sortable">' in doc and "<th>error [m]</th>" in doc
    assert "<pre><code>fixed   width\n  text  &lt;kept&gt;</code></pre>" in doc
    assert "<em>every</em>" in doc and "<strong>bold</strong>" in doc and "<code>code</code>" in doc
    assert '<a href="https://example.org">link</a>' in doc
    assert "<ul><li>first item</li><li>second item</li></ul>" in doc
    assert "<title>A report with every piece</title>" in doc


def test_a_long_report_gets_a_contents_list_and_unique_heading_ids():
    md = "# R\n\nintro\n\n" + "".join(f"## Part\n\ntext {i}\n\n" for i in range(3))
    body, title, headings = markdown_to_html(md)
    assert title == "R" and [h[1] for h in headings] == ["r", "part", "part-2", "part-3"]
    doc = render(md)
    assert doc.index("<nav>") < doc.index('<h2 id="part">') and '<a href="#part-3">Part</a>' in doc


def test_sweep_writes_report_md_and_a_self_contained_report_html(sweep_study):
    out = sweep_study.out
    md, doc = (out / "report.md").read_text(), (out / "report.html").read_text()
    assert words(text_of_html(doc)) == words(text_of_markdown(md))
    assert doc.count("data:image/png;base64,") == 1 and "not found" not in doc
    assert sweep_study.exit_code == 1  # 0.5 s runs miss the scenario's tail bound: listed in the report
    for row in sweep_study.rows:
        assert row["status"] == "failed" and f"- `{row['run']}`: failed (tail RMS tracking error" in md
    assert "| law.k | mean rms_tracking_error_tail [m] | ok/total |" in md


@pytest.fixture(scope="module")
def sweep_study(tmp_path_factory):
    from adaptive_mj import study

    return study.sweep("heave_tracking", grid={"law.k": [100, 200]}, overrides=["simulation.duration=0.5"],
                       out=tmp_path_factory.mktemp("sweep") / "s", jobs=1)


# ------------------------------------------------------------------ in a browser
def blank(png_bytes: bytes) -> bool:
    """A screenshot with (almost) nothing on it: under 0.5 % of its pixels differ from its most common colour,
    or fewer than 8 grey levels."""
    from PIL import Image

    grey = np.asarray(Image.open(io.BytesIO(png_bytes)).convert("L"), dtype=np.uint8)
    counts = np.bincount(grey.ravel(), minlength=256)
    return counts.max() > 0.995 * grey.size or np.count_nonzero(counts) < 8


needs_browser = pytest.mark.skipif(find_browser() is None, reason=NO_BROWSER)


@needs_browser
def test_chromium_shows_the_report_without_errors_and_sorts_its_table(report, tmp_path):
    out = write_html(report)
    with Browser(width=1000, height=1200) as b:
        page = b.open(out)
        assert page.errors == [], page.errors
        assert b.evaluate("performance.getEntriesByType('resource').length") == 0  # self-contained
        assert b.evaluate("Array.from(document.images).map(i => i.complete && i.naturalWidth > 0)") == [True]
        b.evaluate("document.querySelector('table.sortable th:nth-child(2)').click()")
        assert b.evaluate("Array.from(document.querySelectorAll('table.sortable tbody tr td:first-child'))"
                          ".map(td => td.textContent)") == ["c", "a", "b"]  # -1e-3 < 2.5 < 10
        b.evaluate("document.querySelector('table.sortable th:nth-child(2)').click()")
        assert b.evaluate("Array.from(document.querySelectorAll('table.sortable tbody tr td:first-child'))"
                          ".map(td => td.textContent)") == ["b", "a", "c"]
        shot = b.screenshot()
        assert page.errors == [], page.errors
    (tmp_path / "screenshot.png").write_bytes(shot)
    assert shot[:8] == b"\x89PNG\r\n\x1a\n" and not blank(shot)


@needs_browser
def test_chromium_opens_a_sweeps_report_html(sweep_study, tmp_path):
    with Browser() as b:
        page = b.open(sweep_study.html)
        assert b.evaluate("document.title") == "Sweep of heave_tracking"
        assert b.evaluate("Array.from(document.images).every(i => i.complete && i.naturalWidth > 600)")
        assert b.evaluate("document.querySelectorAll('table.sortable tbody tr').length") == 2
        assert b.evaluate("performance.getEntriesByType('resource').length") == 0
        shot = b.screenshot()
    assert page.errors == [], page.errors
    assert not blank(shot)


@needs_browser
def test_the_browser_check_sees_errors_and_blank_pages(tmp_path):
    """The checks above can fail: a script error and a missing image are reported, an empty page is blank."""
    bad = tmp_path / "bad.html"
    bad.write_text("<!DOCTYPE html><html><body><p>x</p><img src='gone.png'>"
                   "<script>console.error('broken'); undefinedFunction();</script></body></html>")
    empty = tmp_path / "empty.html"
    empty.write_text("<!DOCTYPE html><html><body></body></html>")
    with Browser() as b:
        errors = b.open(bad).errors
    assert any("broken" in e for e in errors) and any("undefinedFunction" in e for e in errors)
    assert any("gone.png" in e for e in errors), errors
    with Browser() as b:
        b.open(empty)
        assert blank(b.screenshot())
