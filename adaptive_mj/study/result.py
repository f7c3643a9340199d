"""What a study gives back to Python (adaptive_mj.study.api): a Study, whose rows are plain dicts,
and a Table over them that needs no pandas (columns by name, text and Markdown, HTML in a notebook).
"""
from __future__ import annotations

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
        cells = [list(self.columns)] + [[cell(row.get(c)) for c in self.columns] for row in self.rows]
        widths = [max(len(r[i]) for r in cells) for i in range(len(self.columns))]
        return "\n".join("  ".join(v.rjust(w) for v, w in zip(r, widths, strict=True)) for r in cells)

    def to_markdown(self) -> str:
        def md(v: Any) -> str:
            return cell(v).replace("|", "\\|").replace("\n", " ")

        lines = ["| " + " | ".join(md(c) for c in self.columns) + " |", "|" + "---|" * len(self.columns)]
        lines += ["| " + " | ".join(md(row.get(c)) for c in self.columns) + " |" for row in self.rows]
        return "\n".join(lines)

    def _repr_html_(self) -> str:  # Jupyter shows a table as HTML
        from adaptive_mj.report.html import markdown_to_html

        return markdown_to_html(self.to_markdown())[0]


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
