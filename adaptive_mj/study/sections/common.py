"""What the bench's sections share: Section and SectionReport, the registry the section modules add
themselves to (register, entries), and the helpers several sections use (a job per run, a row of the
main table, a figure saved under figures/, numbers formatted for the tables). The helpers keep their
leading underscore: they are this package's own, not adaptive_mj's API.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import matplotlib

from adaptive_mj.plants import kinds as units  # the units each plant kind declares
from adaptive_mj.setup import scenario as sc
from adaptive_mj.study import analysis
from adaptive_mj.study.job import as_expected
from adaptive_mj.study.parallel import RunSpec, RunOutcome
from adaptive_mj.trajectory import Status

matplotlib.use("Agg")
# the sections import plt from here, so that matplotlib.use("Agg") (figures drawn headless) comes first
import matplotlib.pyplot as plt  # noqa: E402 (after matplotlib.use("Agg"), see above)

SCN = sc.SCENARIOS_DIR


@dataclass
class SectionReport:
    text: str
    rows: list[dict] = field(default_factory=list)


Analyze = Callable[[dict[str, RunOutcome], Path], SectionReport]  # (results by tag, output folder) -> report
Built = tuple[tuple[RunSpec, ...], Analyze]  # what a section module's build gives: its runs and their analysis


@dataclass(frozen=True)
class Section:
    """One section of a bench: its runs and the analysis that turns their results (by tag) into report text
    and main-table rows, figures written under the output folder."""
    key: str
    title: str
    claim: str
    jobs: tuple[RunSpec, ...]
    analyze: Analyze


@dataclass(frozen=True)
class CatalogueEntry:
    """A catalogue section as its module declares it: number (its place in the report, "N. title"), key
    (the tags' and logs' prefix), title, the lecture's claim, and build(quick, logs, **options) -> (the
    runs, the analysis of their results). Called like build, it gives the Section of one bench."""
    number: int
    key: str
    title: str
    claim: str
    build: Callable[..., Built]

    def __call__(self, quick: bool, logs: Path, **options) -> Section:
        jobs, analyze = self.build(quick, logs, **options)
        return Section(self.key, f"{self.number}. {self.title}", self.claim, tuple(jobs), analyze)


REGISTRY: dict[str, CatalogueEntry] = {}  # by key; a section module adds itself when imported


def register(number: int, key: str, title: str, claim: str) -> Callable[[Callable], CatalogueEntry]:
    """Decorator: add the decorated build(quick, logs, **options) -> (jobs, analyze) to the catalogue as
    section `number` and give back its CatalogueEntry (the Section builder)."""
    def add(build: Callable) -> CatalogueEntry:
        clash = [e.key for e in REGISTRY.values() if e.number == number and e.key != key]
        if clash:
            raise ValueError(f"section number {number} is taken by {clash[0]!r} (registering {key!r})")
        entry = CatalogueEntry(number, key, title, claim, build)
        REGISTRY[key] = entry
        return entry

    return add


def entries() -> list[CatalogueEntry]:
    """The registered sections in the report's order (by number)."""
    return sorted(REGISTRY.values(), key=lambda e: e.number)


# ---------------------------------------------------------------- helpers
def _job(section: str, variant: str, scenario: str, logs: Path, overrides=(), extras=(), expect: str = "ok") -> RunSpec:
    """A catalogue run; expect (study.job.RunSpec.expect): "ok", "fail" (a demonstration meant to fail) or "measured"
    (a baseline or a sweep point: its verdict is the measurement)."""
    return RunSpec(scenario=SCN / f"{scenario}.toml", overrides=tuple(overrides),
                   log=logs / f"{section}-{variant}.mcap", tag=f"{section}/{variant}", extras=tuple(extras),
                   expect=expect)


def _ok(r: RunOutcome) -> bool:
    """A run that completed (its verdict "ok" or "failed": both have every row to analyse)."""
    return r.status in (Status.OK, Status.FAILED) and r.trajectory is not None


#: section title -> the plant kind it runs (each kind declares its sections: PlantKind.sections), for the units
#: of its rows
SECTION_PLANT = {section: kind.name for kind in units.built_in().values() for section in kind.sections}


def _row(section: str, variant: str, r: RunOutcome, key: str = "", kind: str | None = None) -> dict:
    """A row of the main table: section (its plant kind's section name, optionally followed by " §N" where one
    kind has several sections), the run, its status, what it was declared for (RunSpec.expect) and whether it ended so,
    its figures in the plant's units (kind: the plant kind, default the section's)."""
    m = (r.summary or {}).get("metrics", {})
    status = r.status if r.status != Status.ERROR else Status.ERROR
    kind = SECTION_PLANT.get(section.split(" §")[0], "") if kind is None else kind
    return {"section": section, "run": variant, "status": status, "expect": r.job.expect,
            "as_expected": as_expected(r), "tail": m.get("rms_tracking_error_tail"),
            "u_rms": m.get("control_rms"), "u_tv": m.get("control_total_variation"), "key": key,
            "y_unit": units.output_unit(kind), "u_unit": units.control_unit(kind)}


def _status_note(results: dict[str, RunOutcome]) -> str:
    bad = [f"`{tag}`: {r.status}" + (f" ({r.error or (r.summary or {}).get('reason', '')})")
           for tag, r in results.items() if r.status != Status.OK]
    return ("\n\nRuns that did not finish normally: " + "; ".join(bad) + ".\n") if bad else ""


def _save(fig, out: Path, name: str) -> str:
    (out / "figures").mkdir(parents=True, exist_ok=True)
    path = out / "figures" / f"{name}.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return f"![{name}](figures/{name}.png)"


def _unit(name: str, plant: str) -> str:
    return units.param_unit(plant, name)


def _g(v, spec=".3g") -> str:
    return "n/a" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, spec)


def _recovery(recovery: float | None, peak: float | None) -> str:
    """A recovery time [s] as the tables say it: "never" when the error never settles below the threshold,
    "not needed" when it never went above it after the swap (settle time 0), else seconds."""
    if recovery is None:
        return "never"
    if recovery == 0.0 and peak is not None and peak < analysis.SWAP_THRESHOLD:
        return f"not needed (peak < {analysis.SWAP_THRESHOLD} rad)"
    return f"{recovery:.2f} s"


def _final_table(r: RunOutcome, plant: str) -> str:
    if r.summary is None:
        return f"(no result: {r.error})"
    f = r.summary["final"]
    lines = ["| parameter | true | estimate | error |", "|---|---|---|---|"]
    for n, v in f["theta_hat"].items():
        true = f["theta"][n]
        u = _unit(n, plant)
        lines.append(f"| {n} [{u}] | {_g(true, '.4g')} | {_g(v, '.4g')} | {_g(v - true, '+.3g')} |")
    return "\n".join(lines)
