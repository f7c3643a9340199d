"""The scorecard's suite: what `adaptive-mj score` runs on each plant kind, and how it scores, as data with a
version. A card records SUITE_VERSION and the hash of these definitions (`definitions_hash`); `score --merge`
joins only cards of one version and hash. Change anything here that changes a number and bump SUITE_VERSION.

Plants: each plant kind that declares a stress-study row (PlantKind.stress: heave, the 1-DOF arm, the UR5e, the
quadrotor), with its nominal noise and failure bound (PlantKind.nominal_noise, .tail_bound).

Tasks per plant (TASKS). Every seed draws its own task from the task's distribution (ScoreTask.draws, declared by
each plant kind beside its keys), and every law meets the same draw on that seed, so laws are compared pair by pair
(score.draws; the card records the distributions and every seed's draw), and the noise:
  tracking  the plant's tracking scenario under nominal noise: tail RMS error, control RMS and total variation, the
            final parameter error (the truth from the compiled model). Drawn: the reference's amplitude and
            frequency (× U[0.75, 1.25]; the 1-DOF plants also its phases, + U[0, 2π]), on the 1-DOF arm the payload's
            mass (× U[0.5, 2]) and on the 1-DOF plants each parameter's initial estimate (its truth × U[0.5, 2]:
            inside every baseline's projection box); the UR5e starts from the scenario's own estimates (zero), the
            quadrotor (the lemniscate with its 10 g payload unknown) from the bare airframe's parameters;
  change    a parameter change at half the run (heave: the water's density ×1.1; the arms: the payload's mass ×4 or
            the payload swapped; the quadrotor: its payload released), the estimates from the truth: the peak error
            after it and the recovery time;
  hold      holding still under noise with the estimates at the truth (the lecture's drift scenario; the
            quadrotor: a take-off and hover with its payload): the estimates' drift rate.
A crashed run (the quadrotor) has not finished: it fails c_success, whatever its figures.
Stressors per plant (each seed's margins on that seed's drawn task, its estimates at the truth: score.margin_draws):
the breaking-point study's (adaptive_mj.study.stress.stressors: noise, disturbance, delay,
control period, and each kind's own: thruster lag, payload ratio, on the UR5e encoder resolution, a differentiated
velocity's filter, actuator lag and the torque limits; on the quadrotor wind, force, torque, mass added to its
payload at 1 s and a rotor's thrust loss), each searched per seed by bisection.

Scores per plant (RealAIGym's form, docs/METRICS.md "Scorecard"):
  performance  S = c_success · (1 − Σ_i w_i · min(1, c_i / n_i)), over CRITERIA (weights w_i sum to 1, the
               normalisers n_i derived from the plant; the drift's term at least the parameter error's:
               JUDGED_TOGETHER); c_success = 1 when every task's run finished (no divergence) and
               the tracking and hold runs kept their tail RMS error within the plant's bound, else 0;
  robustness   R = the mean over the stressors of where the margin lies in the range searched (0: the low end
               fails; 1: the high end passes; in between on the bisection's own scale, log over a decade or more),
               over those that apply to the law (the control period does not apply to a law with filters
               integrated in its stage states, composite adaptation or L1: n/a on the card).
Both per seed, then the mean and its 95 % t interval over seeds (adaptive_mj.study.stats).
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass

from adaptive_mj.plants.kinds import ScoreTask, built_in

SUITE_VERSION = 3  # 2: the quadrotor's row; R over the stressors that apply to a law; 3: tasks drawn per seed


#: One task of the card (its fields: plants.kinds.ScoreTask); each plant kind declares its own beside its keys
Task = ScoreTask


@dataclass(frozen=True)
class Criterion:
    """A column of the card: `metric` of `task`, lower is better, normalised by `normaliser` (a rule in words,
    evaluated by adaptive_mj.study.score.normaliser) with weight `weight` in S."""

    name: str
    task: str
    metric: str
    unit: str  # "output": the plant's output unit; "control": its control unit; else literal
    normaliser: str
    weight: float
    doc: str


#: The tasks per scored plant row, as each plant kind declares them (PlantKind.stress.tasks), in the registry's order
TASKS: dict[str, tuple[Task, ...]] = {k.stress.name: k.stress.tasks for k in built_in().values()
                                      if k.stress is not None and k.stress.tasks}

CRITERIA: tuple[Criterion, ...] = (
    Criterion("tail_error", "tracking", "tail RMS error", "output", "the plant's failure bound (tail_bound)", 0.30,
              "RMS tracking error over the last 25 % of the tracking run"),
    Criterion("peak_after_change", "change", "peak error after the change", "output", "10 × tail_bound", 0.10,
              "largest |ỹ| (‖q̃‖ on joints) after the change"),
    Criterion("recovery_time", "change", "recovery time", "s", "the time left after the change", 0.10,
              "time after the change from which the error stays below tail_bound (never: the time left)"),
    Criterion("control_rms", "tracking", "control RMS", "control", "the actuator's limit (RMS over joints)", 0.10,
              "RMS of u over the tracking run"),
    Criterion("control_tv_rate", "tracking", "control total variation per second", "control/s",
              "100 × the actuator's limit per s (summed over joints)", 0.10,
              "Σ|Δu| over the tracking run divided by its duration: chattering and noise in u"),
    Criterion("param_error", "tracking", "final parameter error", "-", "1 (100 %)", 0.15,
              "‖θ̂ − θ‖ / ‖θ‖ at the end of the tracking run"),
    Criterion("drift_rate", "hold", "estimate drift rate", "1/100 s", "1 (100 % per 100 s)", 0.15,
              "|slope| of ‖θ̂ − θ̂(t0)‖ / ‖θ‖ while holding still, per 100 s; its penalty is at least the final "
              "parameter error's (JUDGED_TOGETHER)"),
)

#: criteria judged together: the first's penalty is at least the second's. A law whose estimates stay still while
#: holding because it does not adapt at all (a dead-zone wider than the noise, a fixed-parameter law) is not
#: rewarded for it unless it also identified the parameters in the tracking run.
JUDGED_TOGETHER = {"drift_rate": "param_error"}


@dataclass(frozen=True)
class Settings:
    """A suite's size: seeds, bisection steps, the margin runs' duration [s] and each task's duration [s]."""

    name: str
    seeds: int
    steps: int
    stress_duration: float
    durations: tuple[tuple[str, float], ...]  # (task name, duration [s])

    def duration(self, task: str) -> float:
        return dict(self.durations)[task]


#: Seeds per suite, for the half-width of a paired comparison on S: the median pair of laws on the 1-DOF plants
#: differs by seed with a standard deviation of about 0.023 (measured on version 3's quick card, docs/METRICS.md), so
#: t_{0.975, n−1} · 0.023 / √n is 0.057 at 3 seeds, 0.029 at 5 (the quick suite: differences of 0.03 in S resolved)
#: and 0.019 at 8 (the full suite: 0.02).
SUITES = {
    "quick": Settings("quick", seeds=5, steps=6, stress_duration=5.0,
                      durations=(("tracking", 10.0), ("change", 10.0), ("hold", 20.0))),
    "full": Settings("full", seeds=8, steps=8, stress_duration=20.0,
                     durations=(("tracking", 30.0), ("change", 30.0), ("hold", 100.0))),
}


def definitions_hash() -> str:
    """sha256 (first 16 hex digits) of the suite's definitions: version, tasks, criteria, suites."""
    text = json.dumps({"version": SUITE_VERSION, "tasks": {k: [asdict(t) for t in v] for k, v in TASKS.items()},
                       "criteria": [asdict(c) for c in CRITERIA], "together": JUDGED_TOGETHER,
                       "suites": {k: asdict(v) for k, v in SUITES.items()}},
                      sort_keys=True, ensure_ascii=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]
