"""The section of the user's own scenario files (`adaptive-mj bench --scenario FILE`), after the catalogue:
not registered (its runs are the files given), built by user_section.
"""
from __future__ import annotations

from pathlib import Path

from adaptive_mj.plants import kinds as units  # the units each plant kind declares
from adaptive_mj.setup import scenario as sc
from adaptive_mj.study.parallel import RunSpec
from adaptive_mj.study.sections.common import Section, SectionReport, _final_table, _g, _ok, _row, _status_note


def user_section(paths: list[Path], logs: Path) -> Section:
    """A section of the user's own scenarios (any law: built in, or an installed plugin), each
    run as the catalogue's runs are: logged, summarised, its estimates drawn."""
    jobs = tuple(RunSpec(scenario=Path(p), log=logs / f"user-{i}-{Path(p).stem}.mcap", tag=f"user/{i}-{Path(p).stem}")
                 for i, p in enumerate(paths))

    def analyze(res, out):
        lines = ["| scenario | law | status | RMS ỹ | tail RMS ỹ | control RMS |", "|---|---|---|---|---|---|"]
        rows, parts = [], []
        for job in jobs:
            r = res[job.tag]
            scn = sc.load(job.scenario)
            kind = scn.plant.kind
            rows.append(_row("user", job.tag.split("/")[1], r, kind=kind))
            if not _ok(r):
                lines.append(f"| `{job.scenario}` | {scn.law.kind} | {r.status} {r.error} |||")
                continue
            m = r.summary["metrics"]
            yu, uu = units.output_unit(kind), units.control_unit(kind)
            lines.append(f"| `{job.scenario.name}` | {scn.law.kind} | {r.status} | "
                         f"{_g(m.get('rms_tracking_error'))} {yu} | {_g(m.get('rms_tracking_error_tail'))} {yu} | "
                         f"{_g(m.get('control_rms'))} {uu} |")
            if not units.is_rigid_body(kind):  # a multi-joint plant's many parameters: no table of them here
                parts.append(f"`{job.scenario.name}` (law `{scn.law.kind}`), final estimates:\n\n"
                             + _final_table(r, kind))
        return SectionReport(f"{len(jobs)} scenario(s) given with `bench --scenario`, each logged in `logs/` "
                             "like the catalogue's runs.\n\n" + "\n".join(lines) + "\n\n" + "\n\n".join(parts)
                             + _status_note(res), rows)

    return Section("user", "Your scenarios", "(your own runs, beside the lecture's)", jobs, analyze)

