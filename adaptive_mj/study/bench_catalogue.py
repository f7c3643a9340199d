"""The bench catalogue: each part of lecture 7 as runs (scenario + overrides) and an analysis that turns
their results into a report section with measured numbers and figures. Each section is a module of
adaptive_mj/study/sections/ that registers itself (sections.common.register); this module imports them,
in the report's order, and assembles the catalogue. It also keeps the names tests and bench.py use.
"""
from __future__ import annotations

from pathlib import Path

# imported for their registration (each adds its section to sections.common.REGISTRY), in the report's order
from adaptive_mj.study.sections import (  # noqa: F401 (imported to register their sections)
    lecture_first_order,
    phase_space,
    lyapunov,
    second_order_heave,
    nth_order,
    drift_dead_zone,
    payload_swap,
    persistent_excitation,
    manipulator_payload,
    sudden_failure,
    control_rate,
    manipulator_drift,
    manipulator_conditions,
    ship_steering,
    mrac_delay_rohrs,
    wing_rock,
    quadrotor_flight,
)
from adaptive_mj.study.sections.common import Section, SectionReport, _job, _recovery, _row, entries
from adaptive_mj.study.sections.control_rate import CONTROL_RATES_HZ, SampledLoop, sampled_loop
from adaptive_mj.study.sections.manipulator_conditions import ARM_CONDITIONS
from adaptive_mj.study.sections.ship_steering import SHIP_SCENARIOS
from adaptive_mj.study.sections.user_scenarios import user_section

__all__ = ["ARM_CONDITIONS", "CONTROL_RATES_HZ", "SHIP_SCENARIOS", "SampledLoop", "Section", "SectionReport",
           "catalogue", "sampled_loop", "user_section", "_arm_conditions", "_arm_drift", "_control_rate", "_job",
           "_recovery", "_row", "_ship", "_quadrotor"]

# the section builders tests call with their options (quick, logs, duration=...)
_control_rate = control_rate.section
_arm_drift = manipulator_drift.section
_arm_conditions = manipulator_conditions.section
_ship = ship_steering.section
_quadrotor = quadrotor_flight.section


def catalogue(*, quick: bool, logs: Path, full_logs: bool = False) -> list[Section]:
    """Every registered section, in the report's order (by number: the lecture's parts 1-8, then the arms,
    sudden failure, the control rate, the ship, MRAC and wing rock; 14 is bench.py's breaking-point study).
    full_logs: to the sections whose grids log summaries by default (their build takes `full_logs`), every row."""
    import inspect

    return [entry(quick, logs, **({"full_logs": True} if full_logs and "full_logs" in
                                  inspect.signature(entry.build).parameters else {})) for entry in entries()]
