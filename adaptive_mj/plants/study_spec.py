"""What a plant kind's study row (kinds.StressPlant) builds its laws and stressors from, and gives back: the
breaking-point study (adaptive_mj.study.stress) builds a StudyContext from the row's compiled model and calls the
row's `laws(ctx, composite)` and `stressors(ctx, duration)`; the delay and the control period, the same on every
plant, it adds itself. Below the study layer, so that each kind declares its sets in its own module.

A Stressor: what a breaking-point search raises (adaptive_mj.study.breaking_point re-exports it); whole_steps: a
value on whole physics steps. The shared pieces of several kinds' sets: the leak rule (LEAK_TIME), θ as a law
table (theta_table) and the sinusoidal disturbance (sine_disturbance).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

LEAK_TIME = 5.0  # s: σ = γ_1 / LEAK_TIME; ν = γ_1 / (LEAK_TIME σ_s)
#: the projection baselines' box on each positive parameter, as factors on its truth: [θ/2, 2θ] (the scorecard draws
#: the initial estimates within it: kinds.ESTIMATES_DRAW)
BOX = (0.5, 2.0)

#: a study row's laws: (law label, its overrides), for the context and whether to add composite adaptation
LawSet = Callable[["StudyContext", bool], list[tuple[str, list[str]]]]
#: a study row's own stressors (the delay and the control period come after them), for the context and a run's
#: duration [s]
StressorSet = Callable[["StudyContext", float], list["Stressor"]]


def whole_steps(value: float, step: float) -> float:
    """value rounded to a whole multiple of step, at least one step (e.g. a control period [s] in
    physics steps of `step` seconds): round(value / step) · step, computed the same way every time
    so that equal step counts give equal floats."""
    return max(1, round(value / step)) * step


@dataclass(frozen=True)
class Stressor:
    """name: a label; overrides(v) -> the --set expressions that apply stress value v;
    lo, hi: the range searched; integer: round to whole numbers (e.g. delay steps);
    unit: the value's unit for reports; step > 0: every value tried is a whole multiple of step
    (lo and hi must be already; e.g. a control period [s] in physics steps of dt)."""

    name: str
    overrides: Callable[[float], list[str]]
    lo: float
    hi: float
    integer: bool = False
    unit: str = ""
    step: float = 0.0

    @classmethod
    def key(cls, key: str, lo: float, hi: float, *, integer: bool = False, unit: str = "") -> "Stressor":
        """The stressor that sets one scenario key (`sweep --breaking-point KEY=LO:HI`)."""
        fmt = (lambda v: str(int(v))) if integer else repr
        return cls(key, lambda v: [f"{key}={fmt(v)}"], lo, hi, integer, unit)

    @classmethod
    def control_period(cls, lo: float, hi: float, dt: float, *, name: str = "control.period") -> "Stressor":
        """The sampled-data control period T [s] from lo to hi, both rounded to whole physics steps
        of dt (as is every bisection value): each value v sets control.mode = 'sampled' and
        control.period = v (the scenario's loader refuses a period that is not a whole multiple of
        dt)."""
        lo, hi = whole_steps(lo, dt), whole_steps(hi, dt)
        return cls(name, lambda v: ["control.mode='sampled'", f"control.period={v!r}"], lo, hi, unit="s", step=dt)

    def steps_between(self, lo: float, hi: float) -> int:
        """Whole steps from lo to hi (a stressor with a step)."""
        return round(hi / self.step) - round(lo / self.step)


@dataclass(frozen=True)
class StudyContext:
    """What a study row's law and stressor sets read, every number from its scenario (with the row's overrides)
    and its compiled model: name and scenario (the row's, for messages), the kind's output and control units,
    the row's disturbance range [control unit] and law.composite (None: no composite row); the law's parameter
    names (p,), its adaptation gains γ (p,) and law.lam [1/s] (None: unset); the plant's true θ (p,) [each
    parameter's unit]; dt: the physics step [s]; the kind's nominal noise σ_y [output unit]; the scenario's
    plant.payload_mass [kg] (None: unset); plant: the built plant (plants.protocol.Plant: its ctrl_range,
    joint_names, and what its own kind reads of it)."""

    name: str
    scenario: str
    output_unit: str
    control_unit: str
    disturbance: tuple[float, float]
    composite: str | None
    law_names: tuple[str, ...]
    gamma: np.ndarray
    lam: float | None
    theta: np.ndarray
    dt: float
    nominal_noise: float
    payload_mass: float | None
    plant: Any


def theta_table(names, values, *, quoted: bool = False) -> str:
    """Parameters as a law table, e.g. law.theta0's "{m=1.0, c=2.0}" (quoted: each name in quotes, a
    multi-joint plant's "body.param")."""
    q = "'" if quoted else ""
    return "{" + ", ".join(f"{q}{n}{q}={float(v)!r}" for n, v in zip(names, values, strict=True)) + "}"


def box_table(names, values, *, quoted: bool = False) -> str:
    """The box [θ/2, 2θ] on the positive parameters as a law.projection table (quoted: as theta_table)."""
    q = "'" if quoted else ""
    return "{" + ", ".join(f"{q}{n}{q}=[{BOX[0] * float(v)!r}, {BOX[1] * float(v)!r}]"
                           for n, v in zip(names, values, strict=True) if v > 0) + "}"


def sine_disturbance(ctx: StudyContext) -> Stressor:
    """A sinusoidal disturbance (ω = 2 rad/s) of magnitude in the row's range [its control unit]."""
    lo, hi = ctx.disturbance
    return Stressor("disturbance", lambda v: [f"disturbance={{kind='sine', magnitude={v!r}, omega=2.0}}"], lo, hi,
                    unit=ctx.control_unit)


def payload_ratio(m0: float, duration: float) -> Stressor:
    """The payload's mass m0 [kg] × ratio from half the run of `duration` [s] on (a payload_mass event)."""
    t_swap = 0.5 * duration
    return Stressor("payload ratio", lambda v: [f"events=[{{t={t_swap!r}, kind='payload_mass', value={v * m0!r}}}]"],
                    1.0, 100.0, unit="×")


def surface_noise(n_axes: int, lam: float, sig: float) -> float:
    """The noise in ‖s‖, s = ė + λ e on n_axes axes, under noise σ on e and 10 σ on ė."""
    return float(np.sqrt(n_axes * ((10 * sig) ** 2 + lam**2 * sig**2)))


def hold_constant(plant: Any, start: Any) -> str:
    """The reference held at its start y_d(0) (a plant of one output): a constant reference (a template: {{ }} is
    one brace, as the scorecard's tasks are written)."""
    return f"reference={{{{kind='constant', value={float(start)!r}}}}}"


def hold_joints(plant: Any, start: Any) -> str:
    """Every joint held at its start y_d(0) (m,) [rad]: a joint sum of sines of zero amplitude about it (a
    template, as hold_constant)."""
    import json

    center = ", ".join(f"{json.dumps(j)}={float(v)!r}" for j, v in zip(plant.joint_names, start, strict=True))
    return "reference={{kind='joint_sum_of_sines', center={{" + center + "}}, amplitudes=[0.0], omegas=[1.0]}}"
