"""What a study gives back to Python (adaptive_mj.study.api): a Study, whose rows are plain dicts,
and the one Table every study's results are written through, with no pandas: columns by name, aligned text
for a terminal, Markdown for a report (and so HTML), CSV and JSON lines for analysis (`Table.write` picks by
the file's suffix). A table's cells are its values: numbers stay numbers in CSV and JSON lines, and are shown
to 4 significant digits in text and Markdown; a cell that is already text (a margin with its bracket, a score
with its interval) is written as it is.
"""
from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence


def cell(value: Any) -> str:
    """A value as a table shows it: floats to 4 significant digits, None and NaN as n/a."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a" if value is None or math.isnan(value) else str(value)
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


@dataclass(frozen=True)
class Table:
    """Rows (dicts) under named columns: `table["seed"]` is a column as a list, `len(table)` the rows,
    iterating gives the rows; str() is aligned text, to_markdown() a Markdown table."""

    columns: tuple[str, ...]
    rows: tuple[Mapping[str, Any], ...]

    @classmethod
    def of(cls, rows: Sequence[Mapping[str, Any]], columns: Sequence[str] | None = None) -> "Table":
        """A table of `rows`; columns: every key in the order first seen, unless given."""
        if columns is None:
            columns = list(dict.fromkeys(k for row in rows for k in row))
        return cls(tuple(columns), tuple(rows))

    def __len__(self) -> int:
        return len(self.rows)

    def __iter__(self) -> Iterator[Mapping[str, Any]]:
        return iter(self.rows)

    def __getitem__(self, column: str) -> list[Any]:
        if column not in self.columns:
            raise KeyError(f"no column {column!r}; the columns are {', '.join(self.columns)}")
        return [row.get(column) for row in self.rows]

    def __str__(self) -> str:
        return self.to_text()

    def to_text(self, *, left: Sequence[str] = (), rule: bool = False) -> str:
        """Aligned text, one line per row under the column names: columns in `left` left-aligned, the others
        right-aligned; rule: a line of dashes under the names."""
        cells = [list(self.columns)] + [[cell(row.get(c)) for c in self.columns] for row in self.rows]
        widths = [max(len(r[i]) for r in cells) for i in range(len(self.columns))]
        lines = ["  ".join(v.ljust(w) if c in left else v.rjust(w)
                           for v, w, c in zip(r, widths, self.columns, strict=True)).rstrip() for r in cells]
        if rule:
            lines.insert(1, "-" * max(len(line) for line in lines))
        return "\n".join(lines)

    def to_markdown(self) -> str:
        def md(v: Any) -> str:
            return cell(v).replace("|", "\\|").replace("\n", " ")

        lines = ["| " + " | ".join(md(c) for c in self.columns) + " |", "|" + "---|" * len(self.columns)]
        lines += ["| " + " | ".join(md(row.get(c)) for c in self.columns) + " |" for row in self.rows]
        return "\n".join(lines)

    def to_html(self) -> str:
        """An HTML table (the report's renderer of to_markdown; Jupyter shows a Table so)."""
        from adaptive_mj.report.html import markdown_to_html

        return markdown_to_html(self.to_markdown())[0]

    def _repr_html_(self) -> str:  # Jupyter shows a table as HTML
        return self.to_html()

    def to_csv(self, path: Path | str) -> Path:
        """CSV with a header of the column names; a value as it is (None empty, a list or dict as JSON)."""
        path = Path(path)
        with path.open("w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            w.writerow(self.columns)
            w.writerows([_csv_value(row.get(c)) for c in self.columns] for row in self.rows)
        return path

    def to_jsonl(self, path: Path | str) -> Path:
        """JSON lines: one object per row, its columns in order (a non-finite float as null)."""
        path = Path(path)
        with path.open("w", encoding="utf-8") as f:
            for row in self.rows:
                f.write(json.dumps({c: _json_value(row.get(c)) for c in self.columns}, ensure_ascii=False) + "\n")
        return path

    def write(self, path: Path | str) -> Path:
        """The table in the format its file's suffix names: .csv, .jsonl, .md or .html; one line otherwise."""
        path = Path(path)
        writers = {".csv": self.to_csv, ".jsonl": self.to_jsonl}
        if path.suffix in writers:
            return writers[path.suffix](path)
        texts = {".md": self.to_markdown, ".html": self.to_html}
        if path.suffix not in texts:
            raise ValueError(f"{path}: a table is written as .csv, .jsonl, .md or .html, not {path.suffix!r}")
        path.write_text(texts[path.suffix]() + "\n", encoding="utf-8")
        return path


def _json_value(value: Any) -> Any:
    """A cell for JSON: a non-finite float as None (JSON has no inf or NaN), containers element-wise."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, (list, tuple)):
        return [_json_value(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): _json_value(v) for k, v in value.items()}
    return value


def _csv_value(value: Any) -> Any:
    """A cell for CSV: None empty, a list or mapping as JSON, anything else as csv writes it."""
    if value is None:
        return ""
    if isinstance(value, (list, tuple, Mapping)):
        return json.dumps(_json_value(value), ensure_ascii=False)
    return value


@dataclass(frozen=True, eq=False)
class Study:
    """A finished study.

    kind: "sweep", "breaking_point", "stress" or "bench"; out: its output folder;
    exit_code: the command's (0 every run ok, 1 some run failed, crashed or diverged);
    report / html: report.md and report.html in `out`;
    text: what the command prints as its result; notes: what it says on stderr after it;
    info: the study's own figures (a sweep: its keys, metrics and counts; a breaking point: its margin).
    rows (a list of dicts, one per run, margin or bench row) are read when first asked for."""

    kind: str
    out: Path
    exit_code: int
    report: Path | None
    html: Path | None
    text: str
    notes: tuple[str, ...] = ()
    info: Mapping[str, Any] = field(default_factory=dict)
    load_rows: Callable[[], list[dict[str, Any]]] = field(default=list, repr=False)
    columns: tuple[str, ...] | None = None
    plotter: Callable[..., Path] | None = field(default=None, repr=False)

    @property
    def ok(self) -> bool:
        return self.exit_code == 0

    @cached_property
    def rows(self) -> list[dict[str, Any]]:
        return self.load_rows()

    @property
    def table(self) -> Table:
        return Table.of(self.rows, self.columns)

    def plot(self, path: Path | str | None = None, **options: Any) -> Path:
        """Draw the study to `path` (default: a PNG in `out`) and return the path: a sweep, its metrics against
        the grid (option `metrics=[...]`); a breaking point, each seed's tail error at each value tried; the
        stress study, every margin's place in its range (plant/law × stressor); the bench, every run's tail
        error, one panel per unit."""
        if self.plotter is None:
            raise ValueError(f"this {self.kind} study has nothing to draw")
        return self.plotter(None if path is None else Path(path), **options)
