"""Mutation testing of chosen modules against their own tests (issue 54): how many realistic single-point bugs
the tests catch.

    .venv/bin/python tools/mutate.py stats score            # named modules (keys of MODULES)
    .venv/bin/python tools/mutate.py --all                  # every module in MODULES
    .venv/bin/python tools/mutate.py stats --list           # the mutants, not run

Each mutant is one change to one node of the module's syntax tree, inside the functions MODULES names for it:
an arithmetic operator swapped (+ -, * /, ** *), a comparison flipped or loosened (< <=, == !=, in / not in, is /
is not), and / or swapped, a `not` or a unary minus dropped, a term of a sum dropped, a number tweaked (an int
+1, 0.0 -> 1.0, any other float x2), True / False swapped, min / max and any / all swapped, a `continue` or
`break` made a `pass`, an augmented assignment's operator swapped.

The source file is never written: a mutant is compiled from the edited tree and served to the import system in a
forked child process (a meta-path finder that answers for the module's name), which runs pytest on the module's
own test files (MODULES) with -x and a per-mutant timeout. Interrupting the tool leaves nothing behind. The parent
imports the heavy third-party packages once (numpy, scipy, mujoco, numba, pytest), so a mutant costs its tests'
own time plus adaptive_mj's import.

A mutant is *killed* when the tests fail, *timeout* when they run past the limit (counted as killed: the bug is
noticed), *survived* when they pass. A survivor known to be equivalent (no input tells it from the original) or
to change only behaviour nobody relies on is listed in EQUIVALENT with its reason and counted apart: the score is
killed / (total − equivalent). Run it for every module an issue changes before the issue is resolved, and put the
score in the closing note; it is not part of CI's default run (minutes per module).
"""
from __future__ import annotations

import argparse
import ast
import copy
import importlib.abc
import importlib.util
import os
import signal
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


@dataclass(frozen=True)
class Target:
    """A module to mutate: its file (relative to the repository), its own test files, and the functions (qualified
    names; a class's name covers its methods; None: the whole module, its constants included) to mutate."""

    path: str
    tests: tuple[str, ...]
    functions: tuple[str, ...] | None = None


SCORING_TESTS = ("tests/test_stats.py", "tests/test_scoring_pinned.py")
SEARCH_TESTS = ("tests/test_search_pinned.py",)
MODULES: dict[str, Target] = {
    "stats": Target("adaptive_mj/study/stats.py", SCORING_TESTS),
    # the scoring functions (no runs); the rest of score.py sets up and runs the card's runs (tests/test_score.py)
    "score": Target("adaptive_mj/study/score.py", SCORING_TESTS,
                    ("_param_error", "_completed", "seed_figures", "performance", "normalisers", "stressor_figures",
                     "figure", "law_figures", "criteria_spread", "rank_laws", "_drawn")),
    "score_suite": Target("adaptive_mj/study/score_suite.py", SCORING_TESTS),
    # the card's tables and sentences (the figures' plotting and the files it writes: tests/test_score.py)
    "score_card": Target("adaptive_mj/study/score_card.py", SCORING_TESTS,
                         ("_unit", "_order", "_name", "_with_n", "leaderboard", "margins_table", "terminal_table",
                          "separated_text", "saturated_text", "runs_text", "_cell")),
    # the one bisection and its bookkeeping (the runs themselves are replaced by hand-filled outcomes)
    "breaking_point": Target("adaptive_mj/study/breaking_point.py", SEARCH_TESTS,
                             ("Search", "Evaluation", "Margin", "_file_name", "_mid", "_midpoints", "_Batches",
                              "search_all", "margin_text")),
    # the stress study's arithmetic and text (its plants, laws and stressors come from the kinds: other tests)
    "stress": Target("adaptive_mj/study/stress.py", SEARCH_TESTS,
                     ("margin_position", "unseparated_text", "margin_text_of", "preflight_text", "_cell", "table")),
    # the quadrotor's margin and when2fail over hand-filled evaluations, and its grid
    "flight_study": Target("adaptive_mj/study/flight.py", SEARCH_TESTS,
                           ("Search", "grid", "bracket_text", "grid_results")),
    # AdaptiveQuadBench's protocol and the flight study on both airframes (issue 52): the seeded draw, the delay
    # test's scan, the success curves and the vehicles' ranges, over hand-filled outcomes (no run flies)
    "flight_protocol": Target("adaptive_mj/study/flight.py",
                              ("tests/test_flight_protocol_pinned.py", "tests/test_aqb_protocol.py",
                               "tests/test_flight_airframes.py"),
                              ("aqb_succeeded", "aqb_delay_succeeded", "scan_results", "scan_margins", "_toggle_times",
                               "draw_task", "TaskDraw", "protocol_levels", "success_curves", "_size", "Vehicle",
                               "VehicleSize", "AQBDelayTest", "AQBProtocol")),
    # the physically consistent projection (pure numpy; the MuJoCo runs of tests/test_consistent_projection.py are
    # left to the suite)
    "pseudo_inertia": Target("adaptive_mj/laws/pseudo_inertia.py", ("tests/test_projection_pinned.py",)),
    # the flight plant's crash check, attitude measurement and events (where they act: the actuators, xfrc_applied)
    "quadrotor": Target("adaptive_mj/plants/quadrotor.py", ("tests/test_flight_pinned.py",),
                        ("rotvec_into", "measure_into", "rotation_vector", "crash_check", "crash_text", "_rotor",
                         "_force", "QuadrotorPlant.set_state", "QuadrotorPlant.step", "QuadrotorPlant._check_crash",
                         "QuadrotorPlant.scale_rotor", "QuadrotorPlant.add_force")),
    # RotorPy's rotor drag (as plain Python) and the allocation's clipped inverse
    "airframe": Target("adaptive_mj/plants/airframe.py", ("tests/test_flight_pinned.py",),
                       ("Airframe.has_drag", "Airframe.thrusts", "rotor_drag_into")),
    # the flight laws' kernel, in two runs (about 900 and 700 mutants): the law itself (geometric, geometric adaptive,
    # the adapted inertia, L1's thrust and moment terms, the logged s) and its helpers (the rotation, the inertia's
    # regressor and rates, the dead-zone, the allocation, L1's update)
    "flight_law": Target("adaptive_mj/laws/flight_kernel.py", ("tests/test_flight_law_pinned.py",), ("flight_law",)),
    "flight_kernel": Target("adaptive_mj/laws/flight_kernel.py", ("tests/test_flight_law_pinned.py",),
                            ("rodrigues", "inertia_times", "inertia_regressor", "inertia_rate", "translation_rates",
                             "allocate", "l1_update")),
    # the estimate's clip into its box, the leakage and the box's tangent cone, the dead-zone's boundary
    "common": Target("adaptive_mj/laws/common.py", ("tests/test_common_pinned.py",),
                     ("clip_into", "modify_rate", "dead_zone_open")),
}

#: (module key, qualified function, mutation[, the mutated line's source, stripped]) -> why no test should kill it
#: (the line where the same mutation text occurs on several lines of one function, not all of them equivalent).
#: Keep each reason checkable.
EQUIVALENT: dict[tuple[str, ...], str] = {
    ("stats", "ranks", "b.lo > a.hi → b.lo >= a.hi"):
        "only reached when separable(a, b): b.lo = a.hi there would need b.hi < a.lo <= a.hi = b.lo",
    ("stats", "ranks", "b.hi < a.lo → b.hi <= a.lo"):
        "only reached when separable(a, b): b.hi = a.lo there would need a.hi < b.lo <= b.hi = a.lo",
    ("stats", "paired_difference", "math.isfinite(x) and math.isfinite(y) → math.isfinite(x) or math.isfinite(y)"):
        "x − y is not finite when either is not, and estimate() leaves non-finite values out",
    ("stats", "paired_difference", "strict=True → strict=False"):
        "zip's strict: the lengths are checked (ValueError) just before",
    ("stats", "paired_ranks", "j == i or not has[j] → j == i and (not has[j])"):
        "a law against itself differs by 0 on every seed, and one with no value pairs on no seed: neither differs",
    ("stats", "paired_ranks", "continue → pass"):
        "the same: a law against itself or against one with no value never differs",
    ("stats", "paired_ranks", "d.lo > 0.0 → d.lo >= 0.0"):
        "only reached when differs(d): d.lo = 0 there would need d.hi < 0 <= d.hi",
    ("stats", "paired_ranks", "d.hi < 0.0 → d.hi <= 0.0"):
        "only reached when differs(d): d.hi = 0 there would need d.lo > 0 >= d.lo",
    ("stats", "separated_pairs", "i + 1 → i"):
        "adds the pairs (i, i): a law against itself differs by 0 on every seed, never separable",
    ("score", "rank_laws", "strict=True → strict=False"):
        "zip's strict: paired_ranks gives one rank per law it is given",
    ("score_card", "_order.key", "1.0 → 2.0"):
        "S lies in [0, 1]: any key below 0 for a law with no S sorts it after every law with one",
    ("score_card", "leaderboard", "strict=True → strict=False"):
        "zip's strict: the cells are built one per column",
    ("score_card", "margins_table", "strict=True → strict=False"):
        "zip's strict (twice): a stressor's margins and first fails are per seed, and the cells one per column",
    ("breaking_point", "_Batches.run", "strict=True → strict=False"):
        "zip's strict: run_jobs gives one outcome per job",
    ("breaking_point", "_Batches.evaluate", "strict=True → strict=False"):
        "zip's strict: one chunk of outcomes per (search, value) asked for",
    ("breaking_point", "_Batches.complete_first_fails", "len(ev.tails) < self.seeds → len(ev.tails) <= self.seeds"):
        "a first fail already run on every seed asks for an empty range of seeds: no run, no change",
    ("breaking_point", "_Batches.complete_first_fails", "strict=True → strict=False"):
        "zip's strict: one chunk of outcomes per first fail asked for",
    ("breaking_point", "search_all", "strict=True → strict=False"):
        "zip's strict: one Evaluation per (search, value) asked for",
    ("stress", "preflight_text", "strict=True → strict=False"):
        "zip's strict: an Evaluation's predictions and tails are per seed",
    ("flight_study", "Search.margin", "v > lo → v >= lo"):
        "lo is a value where every seed succeeded, so it is never among the failing values compared with it",
    ("flight_study", "Search.when2fail", "v < hi → v <= hi"):
        "hi is a value where every seed failed, so it is never among the succeeding values compared with it",
    ("breaking_point", "_Batches.__init__", "seeds > 1 → seeds >= 1"):
        "screening one seed skips nothing: a value's other seeds are none",
}
_INTEGER_CLAMP = ("_midpoints stops an integer search at a bracket of width <= 1; in a wider one with whole ends "
                  "round(mid) lies strictly inside (linear: within 1/2 of a middle >= 1 from each end; geometric: "
                  "sqrt(lo hi) >= 3.16 lo >= lo + 1 and <= hi / 3.16), so this clamp is never reached; a search "
                  "with non-whole ends on an integer stressor is not made by any study")
_STEP_CLAMP = ("_midpoints stops a stepped search at a bracket of one step; in a wider one the middle's whole step "
               "lies strictly inside (linear: (n_lo + n_hi) / 2; geometric from lo >= one step: sqrt(n_lo n_hi) >= "
               "3.16 n_lo >= n_lo + 1 and <= n_hi / 3.16), so this clamp is never reached")
EQUIVALENT.update({("breaking_point", "_mid", text): _INTEGER_CLAMP for text in (
    "v <= lo → v < lo", "lo + 1 → lo - 1", "lo + 1 → lo", "v >= hi → v > hi", "hi - 1 → hi + 1", "hi - 1 → hi",
    "1 → 2")})
_SCRATCH = "a scratch array made larger than it needs: only its first entries are written and read"
EQUIVALENT.update({("pseudo_inertia", where, text, line): _SCRATCH for where, text, line in (
    ("symmetric_eigen", "4 → 5", "B = np.empty((4, 4))"),
    ("smallest_eigenvalue", "4 → 5", "w, V = np.empty(4), np.empty((4, 4))"),
    ("psd_part", "4 → 5", "w, V = np.empty(4), np.empty((4, 4))"),
    ("objective_gradient", "10 → 11", "r = np.empty(10)"),
    ("project_body", "4 → 5", "J = np.empty((4, 4))"),
    ("project_body", "10 → 11", "target = np.empty(start + 10)"),
    ("project_body", "10 → 11", "work = np.empty(start + 10)"),
    ("project_body", "4 → 5", "X, X_prev, Y, G, step = np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4)), "
                              "np.empty((4, 4)), np.empty((4, 4))"))})
_TOLERANCE = ("the Jacobi sweeps' stopping threshold moved within rounding (or made absolute, the same for "
              "matrices of order one): the same decomposition to 1e-15 and no more than the 30 rotations "
              "tests/test_projection_pinned.py allows (checked by hand); only a threshold nobody chose differs")
EQUIVALENT.update({("pseudo_inertia", "symmetric_eigen", text, line): _TOLERANCE for text, line in (
    ("0.0 → 1.0", "scale = 0.0"),
    ("B[i, i] * B[i, i] → B[i, i] / B[i, i]", "scale += B[i, i] * B[i, i]"),
    ("0.0 → 1.0", "if off == 0.0 or off <= 1e-36 * scale:"),
    ("off <= 1e-36 * scale → off < 1e-36 * scale", "if off == 0.0 or off <= 1e-36 * scale:"),
    ("1e-36 * scale → 1e-36 / scale", "if off == 0.0 or off <= 1e-36 * scale:"),
    ("1e-36 → 2e-36", "if off == 0.0 or off <= 1e-36 * scale:"))})
EQUIVALENT.update({
    ("pseudo_inertia", "symmetric_eigen", "60 → 61"): "a 61st sweep is never reached: it converges in about 5",
    ("pseudo_inertia", "symmetric_eigen", "n - 1 → n + 1"): "the extra p have an empty range of q > p",
    ("pseudo_inertia", "symmetric_eigen", "n - 1 → n"): "the extra p has an empty range of q > p",
    ("pseudo_inertia", "symmetric_eigen", "theta >= 0.0 → theta > 0.0"):
        "at theta = 0 (equal diagonal entries) t = +1 and t = -1 both zero the entry (a rotation by +45 or -45 "
        "degrees): the same eigenvalues, the eigenvectors' signs aside",
    ("pseudo_inertia", "psd_part", "w[k] > 0.0 → w[k] >= 0.0"): "adds the eigenvalue-0 terms, each exactly 0",
    ("pseudo_inertia", "project_body", "moved <= STEP_TOLERANCE * STEP_TOLERANCE * size → moved < STEP_TOLERANCE "
     "* STEP_TOLERANCE * size"): "a step exactly at the tolerance: one more iteration of a converged iterate",
})
_STOP = ("the accelerated gradient's stopping threshold shifted or made absolute (the same for X of order one): "
         "the same iterate to rounding, and no more than the 100 iterations tests/test_projection_pinned.py allows "
         "(checked by hand: 71 and 77 against 73)")
EQUIVALENT.update({("pseudo_inertia", "project_body", text, line): _STOP for text, line in (
    ("0.0 → 1.0", "moved, size = 0.0, 0.0"),  # size's (moved's: killed by the iteration count)
    ("X[i, j] * X[i, j] → X[i, j] / X[i, j]", "size += X[i, j] * X[i, j]"),
    ("STEP_TOLERANCE * STEP_TOLERANCE * size → STEP_TOLERANCE * STEP_TOLERANCE / size",
     "if moved <= STEP_TOLERANCE * STEP_TOLERANCE * size:"))})
EQUIVALENT.update({
    ("pseudo_inertia", "smallest_eigenvalue", "0 → 1", "lo, total = w[0], 0.0"):
        "lo starts from another eigenvalue: the minimum over all four follows",
    ("pseudo_inertia", "psd_part", "4 → 5", "for i in range(4):"): "i = 4 meets an empty range(4, 4) of j",
    ("pseudo_inertia", "_hessian", "4 → 5", "for i in range(4):"): "i = 4 meets an empty range(4, 4) of j",
    ("pseudo_inertia", "_hessian", "10 → 11", "G, work, zero = np.zeros((4, 4)), np.zeros(10), np.zeros(10)"):
        _SCRATCH,
    ("pseudo_inertia", "eigenvalues", "1 → 2", "columns = th.reshape(-1, th.shape[-1]).T  # (n_theta, N): "
     "pseudo_inertia fills J[i, j] (N,) for every row at once"):
        "numpy's reshape (2.x, the pinned 2.4) infers any negative size: -2 reads as -1",
})
# --- the flight plant and the flight laws' kernel
EQUIVALENT.update({
    ("airframe", "rotor_drag_into", "thrust > 0.0 → thrust >= 0.0"):
        "at zero thrust the other branch gives ω = √(0/k_eta) = 0 too",
    ("common", "modify_rate", "rate[i] < 0.0 → rate[i] <= 0.0"): "sets a zero rate to zero",
    ("common", "modify_rate", "rate[i] > 0.0 → rate[i] >= 0.0"): "sets a zero rate to zero",
    ("common", "clip_into", "theta[i] < lower[i] → theta[i] <= lower[i]"): "sets an estimate on its bound to it",
    ("common", "clip_into", "theta[i] > upper[i] → theta[i] >= upper[i]"): "sets an estimate on its bound to it",
    ("flight_kernel", "l1_update", "9 → 10"): "a scratch slice made one longer: inertia_times writes its first three",
    ("flight_kernel", "l1_update", "1.0 → 2.0"):
        "the stand-in for estimates the builder refuses (m̂ = 0 or a singular Ĵ: plants.quadrotor.estimate_problem): "
        "any finite number keeps the step finite (tested); its value is behaviour nobody relies on",
    ("flight_kernel", "allocate", "lim < k → lim <= k"): "k = lim either way",
    ("flight_kernel", "allocate", "1.0 → 2.0", "lim = 1.0"):
        "k starts at 1: a bound of 1 or 2 for a rotor the yaw does not move leaves the minimum as it is",
})
_THRESHOLD = ("a threshold against division by (nearly) zero moved within rounding: at |φ| (or ‖F‖, ‖b₃ × e₁‖) of "
              "1e-12 to 2e-12 the two branches agree to far below a double's rounding, and no input lands there")
EQUIVALENT.update({("flight_kernel", "rodrigues", text): _THRESHOLD for text in (
    "angle < 1e-12 → angle <= 1e-12", "1e-12 → 2e-12")})
EQUIVALENT.update({("flight_law", "flight_law", text, "F[0], F[1], F[2], nF = 0.0, 0.0, 1.0, 1.0"):
                   "one of F's entries left as it was, not zeroed: they are all within 1e-12 of 0 (b₃d moves by under "
                   "1e-12), or one is NaN, when f and so every thrust is NaN either way (the run's own checks end it)"
                   for text in ("0 → 1", "1 → 2")})
EQUIVALENT.update({("flight_law", "flight_law", text): _THRESHOLD for text in (
    "nF > 1e-12 → nF >= 1e-12", "1e-12 → 2e-12", "n2 > 1e-12 → n2 >= 1e-12")})
_FITS = ("only the flag 'a rotor is outside its box' changes, and only for a command that fits (or one flagged "
         "anyway): the yaw-last loop then finds every bound >= 1, so k = 1, and sums the same terms in the same order "
         "(the same u to rounding)")
EQUIVALENT.update({("flight_kernel", "allocate", text, line): _FITS for text, line in (
    ("False → True", "out = False"),
    ("0.0 <= u[i] <= P[P_TMAX + i] → 0.0 < u[i] <= P[P_TMAX + i]", "if not (0.0 <= u[i] <= P[P_TMAX + i]):"),
    ("0.0 <= u[i] <= P[P_TMAX + i] → 0.0 <= u[i] < P[P_TMAX + i]", "if not (0.0 <= u[i] <= P[P_TMAX + i]):"),
    ("0.0 → 1.0", "if not (0.0 <= u[i] <= P[P_TMAX + i]):"))})
_ZERO = ("a term with a factor b₂d's (or ḃ₂d's, b̈₂d's) x component, b20 (d20, f20): 0 by construction (b₂d = b₃d × e₁ "
         "/ ‖·‖ is orthogonal to e₁), so its sign, presence or a division of 0 by it changes nothing")
_ALONG = ("nn, the component along b₃d of b̈₃d (along b₂d of b̈₂d), cancels from Ω̇_d: b̈₃d enters it only as b₁d·b̈₃d, "
          "through c̈ (whose part along c ∥ b₂d the next nn removes) and through b₂d × b̈₃d in b̈₁d (read only as "
          "b₂d·b̈₁d: b₂d·(b₂d × b₃d) = 0); b̈₂d enters only as b₃d·b̈₂d and b̈₂d × b₃d in b̈₁d (read as b₂d·b̈₁d): "
          "b₃d·b₂d = b₂d·(b₂d × b₃d) = 0")
_F10 = "f10, b̈₁d's x component, is read only as b20 * f10 with b20 = 0 (b₂d ⊥ e₁)"
_SCRATCH_VIEW = ("a scratch view made one longer at its end (tmp[12:16], ...): its fourth entry is never read or "
                 "written through it (jw's stops at tmp's end, 24)")
EQUIVALENT.update({
    ("flight_law", "flight_law", "3 → 4", "for a in range(3):"):
        "an extra row a = 3 of E = R_dᵀR writes tmp[12:15], scratch that only the inertia branch uses, after "
        "writing it",
})
EQUIVALENT.update({("flight_law", "flight_law", text, "sR, Wr, ar, jw = tmp[12:15], tmp[15:18], tmp[18:21], "
                    "tmp[21:24]"): _SCRATCH_VIEW for text in ("15 → 16", "18 → 19", "21 → 22", "24 → 25")})
_B1 = "b10, b11, b12 = b21 * b32 - b22 * b31, b22 * b30 - b20 * b32, b20 * b31 - b21 * b30"
_D11 = "d11 = (d22 * b30 - d20 * b32) + (b22 * d30 - b20 * d32)"
_O_RATE = "o0 = b10 * wd0 + b20 * wd1 + b30 * wd2  # R_d Ω_d, world frame"
_F11 = "f11 = (f22 * b30 - f20 * b32) + 2.0 * (d22 * d30 - d20 * d32) + (b22 * f30 - b20 * f32)"
_F12 = "f12 = (f20 * b31 - f21 * b30) + 2.0 * (d20 * d31 - d21 * d30) + (b20 * f31 - b21 * f30)"
_A2 = "a2 = (d20 * d10 + d21 * d11 + d22 * d12) + (b20 * f10 + b21 * f11 + b22 * f12)"
_O_ACC = "o0 = b10 * a0 + b20 * a1 + b30 * a2  # R_d Ω̇_d, world frame"
EQUIVALENT.update({("flight_law", "flight_law", text, line): _ZERO for text, line in (
    ("b22 * b30 - b20 * b32 → b22 * b30 + b20 * b32", _B1), ("b22 * b30 - b20 * b32 → b22 * b30", _B1),
    ("d22 * b30 - d20 * b32 → d22 * b30 + d20 * b32", _D11), ("d22 * b30 - d20 * b32 → d22 * b30", _D11),
    ("b22 * d30 - b20 * d32 → b22 * d30 + b20 * d32", _D11), ("b22 * d30 - b20 * d32 → b22 * d30", _D11),
    ("b10 * wd0 + b20 * wd1 → b10 * wd0 - b20 * wd1", _O_RATE), ("b10 * wd0 + b20 * wd1 → b10 * wd0", _O_RATE),
    ("b22 * f30 - b20 * f32 → b22 * f30 + b20 * f32", _F11), ("b22 * f30 - b20 * f32 → b22 * f30", _F11),
    ("f22 * b30 - f20 * b32 → f22 * b30 + f20 * b32", _F11), ("f22 * b30 - f20 * b32 → f22 * b30", _F11),
    ("b20 * f32 → b20 / f32", _F11), ("f20 * b32 → f20 / b32", _F11),
    ("d22 * d30 - d20 * d32 → d22 * d30 + d20 * d32", _F11), ("d22 * d30 - d20 * d32 → d22 * d30", _F11),
    ("b20 * f31 → b20 / f31", _F12), ("d20 * d31 → d20 / d31", _F12), ("b20 * f10 → b20 / f10", _A2),
    ("b10 * a0 + b20 * a1 → b10 * a0 - b20 * a1", _O_ACC), ("b10 * a0 + b20 * a1 → b10 * a0", _O_ACC),
    ("b20 * a1 → b20 / a1", _O_ACC))})
#: (module key, qualified function, the line's source, stripped) -> why no mutant of that line should be killed: the
#: line's value is never read where it would matter (every mutant of it is equivalent)
EQUIVALENT.update({
    ("flight_protocol", "draw_task", "1.0 + c * u → 1.0 - c * u"):
        "u is U(−1, 1): 1 − c u has the distribution AdaptiveQuadBench states (1 + U(−c, c)); only a seed's value "
        "moves",
    ("flight_protocol", "AQBDelayTest.levels", "12 → 13"):
        "rounding k·step to 12 or 13 decimals gives the same float for every level of a 10 ms grid",
    ("flight_protocol", "_toggle_times", "100 → 101"):
        "one more redraw of a switch time too close to another: the 100th is reached with probability ~0",
    ("flight_protocol", "_toggle_times",
     "min((abs(c - t) for t in times)) >= gap → min((abs(c - t) for t in times)) > gap"):
        "a continuous draw lands exactly one gap from another switch with probability 0",
    ("flight_protocol", "scan_results", "0 → 1"):
        "the columns' count read from the second level instead of the first: every level has the same columns",
    ("flight_protocol", "scan_results", "strict=True → strict=False"):
        "zip's strict: every row has the columns' count by construction (delay_test fills each level)",
    ("flight_protocol", "scan_margins", "0 → 1"):
        "the columns' count read from the second level instead of the first: every level has the same columns",
    ("flight_protocol", "AQBDelayTest.levels", "1e-09 → 2e-09"):
        "a tolerance on a floor: any value far below one step keeps the same count",
    ("flight_protocol", "protocol_levels", "1e-09 → 2e-09"):
        "a tolerance on a floor: any value far below one step keeps the same count",
    ("flight_protocol", "protocol_levels", "12 → 13"):
        "rounding k·step to 12 or 13 decimals gives the same float for every level",
    ("flight_protocol", "_toggle_times", "break → pass", "break"):
        "the `else: break` after 100 failed redraws (the `break` after an append is killed): reached with probability "
        "~0",
    ("flight_protocol", "scan_margins", "12 → 13"):
        "rounding first − step to 12 or 13 decimals gives the same float on a 10 ms grid",
})

EQUIVALENT_LINES: dict[tuple[str, str, str], str] = {
    ("flight_law", "flight_law", "nn = (d30 * Fd0 + d31 * Fd1 + d32 * Fd2) + (b30 * Fs0 + b31 * Fs1 + b32 * Fs2)"):
        _ALONG,
    ("flight_law", "flight_law", "nn = (d21 * c1 + d22 * c2) + (b21 * g1 + b22 * g2)"): _ALONG,
    ("flight_law", "flight_law",
     "f10 = (f21 * b32 - f22 * b31) + 2.0 * (d21 * d32 - d22 * d31) + (b21 * f32 - b22 * f31)"): _F10,
}
EQUIVALENT.update({("breaking_point", "_mid", text): _STEP_CLAMP for text in (
    "lo / st.step → lo * st.step", "n_hi - 1 → n_hi + 1", "n_hi - 1 → n_hi", "n_lo + 1 → n_lo - 1",
    "n_lo + 1 → n_lo")})


# ----------------------------------------------------------------------------------------------- the mutants


@dataclass(frozen=True)
class Mutant:
    index: int  # the node's place in ast.walk order
    kind: str
    arg: object
    line: int
    where: str  # qualified name of the enclosing function ("<module>" outside any)
    text: str  # "before → after"


BINOP_SWAP = {ast.Add: ast.Sub, ast.Sub: ast.Add, ast.Mult: ast.Div, ast.Div: ast.Mult, ast.Pow: ast.Mult,
              ast.FloorDiv: ast.Div, ast.Mod: ast.FloorDiv}
CMP_SWAP = {ast.Lt: ast.LtE, ast.LtE: ast.Lt, ast.Gt: ast.GtE, ast.GtE: ast.Gt, ast.Eq: ast.NotEq, ast.NotEq: ast.Eq,
            ast.Is: ast.IsNot, ast.IsNot: ast.Is, ast.In: ast.NotIn, ast.NotIn: ast.In}
CMP_FLIP = {ast.Lt: ast.Gt, ast.LtE: ast.GtE, ast.Gt: ast.Lt, ast.GtE: ast.LtE}
NAME_SWAP = {"min": "max", "max": "min", "any": "all", "all": "any"}


def _qualnames(tree: ast.Module) -> dict[int, str]:
    """id(node) -> the qualified name of its enclosing function or class ("<module>" at the top)."""
    out: dict[int, str] = {}

    def visit(node: ast.AST, name: str) -> None:
        for child in ast.iter_child_nodes(node):
            inner = name
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                inner = child.name if name == "<module>" else f"{name}.{child.name}"
            out[id(child)] = inner
            visit(child, inner)

    visit(tree, "<module>")
    return out


def _skipped(tree: ast.Module) -> set[int]:
    """Nodes never mutated: docstrings, f-strings, annotations, decorators, asserts, and what they hold."""
    skip: set[int] = set()

    def all_of(node: ast.AST | None) -> None:
        if node is not None:
            skip.update(id(n) for n in ast.walk(node))

    for node in ast.walk(tree):
        if isinstance(node, (ast.JoinedStr, ast.Assert)):
            all_of(node)
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            all_of(node.returns)
            for d in node.decorator_list:
                all_of(d)
            for a in [*node.args.args, *node.args.kwonlyargs, *node.args.posonlyargs, node.args.vararg,
                      node.args.kwarg]:
                if a is not None:
                    all_of(a.annotation)
        elif isinstance(node, ast.AnnAssign):
            all_of(node.annotation)
        elif isinstance(node, ast.ClassDef):
            for d in node.decorator_list:
                all_of(d)
    return skip


def _selected(where: str, functions: tuple[str, ...] | None) -> bool:
    if functions is None:
        return True
    return any(where == f or where.startswith(f + ".") for f in functions)


def _number(value: object) -> bool | int | float:
    """A number tweaked: True/False swapped, an int + 1, 0.0 -> 1.0, any other float doubled."""
    if isinstance(value, bool):
        return not value
    if isinstance(value, int):
        return value + 1
    assert isinstance(value, float)
    return 1.0 if value == 0.0 else 2.0 * value


def _candidates(node: ast.AST) -> list[tuple[str, object, ast.AST]]:
    """The mutants of one node: (kind, its argument, the node as it would read after)."""
    out: list[tuple[str, object, ast.AST]] = []
    if isinstance(node, ast.BinOp):
        swap = BINOP_SWAP.get(type(node.op))
        if swap is not None:
            out.append(("binop", None, ast.BinOp(node.left, swap(), node.right)))
        if isinstance(node.op, (ast.Add, ast.Sub)):
            out.append(("drop_right", None, node.left))
    elif isinstance(node, ast.AugAssign) and type(node.op) in BINOP_SWAP:
        out.append(("binop", None, ast.AugAssign(node.target, BINOP_SWAP[type(node.op)](), node.value)))
    elif isinstance(node, ast.Compare):
        for k, op in enumerate(node.ops):
            for table, kind in ((CMP_SWAP, "cmp"), (CMP_FLIP, "cmp_flip")):
                new = table.get(type(op))
                if new is not None:
                    ops = list(node.ops)
                    ops[k] = new()
                    out.append((kind, k, ast.Compare(node.left, ops, node.comparators)))
    elif isinstance(node, ast.BoolOp):
        out.append(("boolop", None, ast.BoolOp(ast.Or() if isinstance(node.op, ast.And) else ast.And(), node.values)))
    elif isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.Not, ast.USub)):
        out.append(("drop_unary", None, node.operand))
    elif isinstance(node, ast.Constant) and isinstance(node.value, (bool, int, float)):
        out.append(("number", None, ast.Constant(_number(node.value))))
    elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in NAME_SWAP:
        out.append(("name", None, ast.Call(ast.Name(NAME_SWAP[node.func.id]), node.args, node.keywords)))
    elif isinstance(node, (ast.Continue, ast.Break)):
        out.append(("pass", None, ast.Pass()))
    return out


def mutants(tree: ast.Module, functions: tuple[str, ...] | None) -> list[Mutant]:
    """Every mutant of `tree` inside `functions` (module docstring), in source order."""
    names, skip, parents = _qualnames(tree), _skipped(tree), _parents(tree)
    out: list[Mutant] = []
    for index, node in enumerate(ast.walk(tree)):
        where = names.get(id(node), "<module>")
        if id(node) in skip or not _selected(where, functions):
            continue
        parent = parents.get(id(node), (None, "", None))[0]
        name = f"{parent.arg}=" if isinstance(parent, ast.keyword) else ""  # a keyword argument: named
        for kind, arg, after in _candidates(node):
            out.append(Mutant(index, kind, arg, getattr(node, "lineno", 0), where,
                              f"{name}{ast.unparse(node)} → {name}{ast.unparse(after)}"))
    out.sort(key=lambda m: (m.line, m.index))
    return out


def _parents(tree: ast.AST) -> dict[int, tuple[ast.AST, str, int | None]]:
    out: dict[int, tuple[ast.AST, str, int | None]] = {}
    for parent in ast.walk(tree):
        for field, value in ast.iter_fields(parent):
            if isinstance(value, list):
                for i, v in enumerate(value):
                    if isinstance(v, ast.AST):
                        out[id(v)] = (parent, field, i)
            elif isinstance(value, ast.AST):
                out[id(value)] = (parent, field, None)
    return out


def _replace(tree: ast.AST, node: ast.AST, new: ast.AST) -> None:
    parent, field, i = _parents(tree)[id(node)]
    ast.copy_location(new, node)
    if i is None:
        setattr(parent, field, new)
    else:
        getattr(parent, field)[i] = new


def apply(tree: ast.Module, m: Mutant) -> ast.Module:
    """A copy of `tree` with mutant m applied."""
    tree = copy.deepcopy(tree)
    node = list(ast.walk(tree))[m.index]
    if m.kind == "binop":
        assert isinstance(node, (ast.BinOp, ast.AugAssign))
        node.op = BINOP_SWAP[type(node.op)]()
    elif m.kind == "drop_right":
        assert isinstance(node, ast.BinOp)
        _replace(tree, node, node.left)
    elif m.kind in ("cmp", "cmp_flip"):
        assert isinstance(node, ast.Compare) and isinstance(m.arg, int)
        table = CMP_SWAP if m.kind == "cmp" else CMP_FLIP
        node.ops[m.arg] = table[type(node.ops[m.arg])]()
    elif m.kind == "boolop":
        assert isinstance(node, ast.BoolOp)
        node.op = ast.Or() if isinstance(node.op, ast.And) else ast.And()
    elif m.kind == "drop_unary":
        assert isinstance(node, ast.UnaryOp)
        _replace(tree, node, node.operand)
    elif m.kind == "number":
        assert isinstance(node, ast.Constant)
        node.value = _number(node.value)
    elif m.kind == "name":
        assert isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
        node.func.id = NAME_SWAP[node.func.id]
    elif m.kind == "pass":
        _replace(tree, node, ast.Pass())
    return ast.fix_missing_locations(tree)


# ----------------------------------------------------------------------------------------------- running


class _Serve(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Answers the import of one module with a code object (the mutant), from the module's own file name."""

    def __init__(self, name: str, path: Path, code) -> None:
        self.name, self.path, self.code = name, path, code

    def find_spec(self, fullname, path=None, target=None):
        if fullname != self.name:
            return None
        return importlib.util.spec_from_file_location(fullname, self.path, loader=self)

    def create_module(self, spec):
        return None

    def exec_module(self, module) -> None:
        exec(self.code, module.__dict__)


def _run_child(name: str, path: Path, code, tests: tuple[str, ...], timeout: float, log: Path | None) -> str:
    """Run the tests in a forked child with `code` served as module `name` (None: the file as it is): "killed",
    "survived" or "timeout"."""
    pid = os.fork()
    if pid == 0:  # the child: never returns
        rc = 98
        try:
            os.setsid()
            fd = os.open(log if log else os.devnull, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
            os.dup2(fd, 1)
            os.dup2(fd, 2)
            if code is not None:
                sys.meta_path.insert(0, _Serve(name, path, code))
            import pytest

            rc = int(pytest.main(["-x", "-q", "-p", "no:cacheprovider", "-o", "addopts=", *tests]))
        except BaseException:  # noqa: BLE001 (any failure of the child is a failing run; it must not return)
            rc = 99
        finally:
            os._exit(rc)
    deadline = time.monotonic() + timeout
    try:
        while True:
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                return "survived" if os.waitstatus_to_exitcode(status) == 0 else "killed"
            if time.monotonic() > deadline:
                _stop(pid)
                return "timeout"
            time.sleep(0.02)
    except BaseException:  # interrupted (Ctrl-C, SIGTERM): the child goes too, then the error goes on
        _stop(pid)
        raise


def _stop(pid: int) -> None:
    """Kill the child's own process group (setsid: it and what it started) and reap it."""
    try:
        os.killpg(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    except (ProcessLookupError, ChildProcessError):
        pass


def _module_name(path: str) -> str:
    return path.removesuffix(".py").replace("/", ".")


def run_module(key: str, *, timeout: float | None, listing: bool, verbose: bool) -> dict:
    target = MODULES[key]
    path = ROOT / target.path
    source = path.read_text(encoding="utf-8")
    lines = source.splitlines()
    tree = ast.parse(source, filename=str(path))
    found = mutants(tree, target.functions)
    if listing:
        for m in found:
            print(f"{target.path}:{m.line} [{m.where}] {m.text}")
        return {"total": len(found)}
    name = _module_name(target.path)
    tests = tuple(str(ROOT / t) for t in target.tests)
    t0 = time.monotonic()
    log = Path(tempfile.gettempdir()) / f"mutate-{key}-baseline.log"
    base = _run_child(name, path, None, tests, 600.0, log)
    took = time.monotonic() - t0
    if base != "survived":
        print(f"{key}: its tests fail without any mutant (their output: {log}); not run", flush=True)
        return {"error": True}
    log.unlink()
    limit = timeout if timeout is not None else max(20.0, 4.0 * took)
    print(f"{key}: {len(found)} mutants of {target.path}, tests {', '.join(target.tests)} "
          f"({took:.1f} s unmutated; {limit:.0f} s limit each)", flush=True)
    counts = {"killed": 0, "timeout": 0, "survived": 0, "equivalent": 0}
    survivors = []
    for n, m in enumerate(found, start=1):
        code = compile(apply(tree, m), str(path), "exec", dont_inherit=True)
        verdict = _run_child(name, path, code, tests, limit, None)
        line = lines[m.line - 1].strip()
        why = (EQUIVALENT.get((key, m.where, m.text, line)) or EQUIVALENT.get((key, m.where, m.text))
               or EQUIVALENT_LINES.get((key, m.where, line)))
        if verdict == "survived" and why is not None:
            verdict = "equivalent"
        counts[verdict] += 1
        if verdict in ("survived", "equivalent"):
            survivors.append((m, verdict, why))
        if verbose or verdict == "survived":
            print(f"  [{n}/{len(found)}] {verdict}: {target.path}:{m.line} [{m.where}] {m.text}", flush=True)
    counted = len(found) - counts["equivalent"]
    score = (counts["killed"] + counts["timeout"]) / counted if counted else 1.0
    print(f"{key}: killed {counts['killed']}, timeout {counts['timeout']}, survived {counts['survived']}, "
          f"equivalent {counts['equivalent']} of {len(found)}: {100 * score:.1f} % of the non-equivalent killed "
          f"({time.monotonic() - t0:.0f} s)", flush=True)
    for m, verdict, why in survivors:
        print(f"  {verdict}: {target.path}:{m.line} [{m.where}] {m.text}" + (f"  ({why})" if why else ""))
    return {**counts, "total": len(found), "score": score}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("modules", nargs="*", help=f"modules to mutate, of: {', '.join(MODULES)}")
    parser.add_argument("--all", action="store_true", help="every module in MODULES")
    parser.add_argument("--list", action="store_true", help="list the mutants, run nothing")
    parser.add_argument("--timeout", type=float, default=None,
                        help="seconds per mutant (default: 4 x the unmutated tests' time, at least 20)")
    parser.add_argument("--functions", default=None,
                        help="comma-separated qualified names: mutate only these (default: MODULES' choice)")
    parser.add_argument("-v", "--verbose", action="store_true", help="print every mutant's verdict")
    args = parser.parse_args(argv)
    keys = list(MODULES) if args.all else args.modules
    unknown = [k for k in keys if k not in MODULES]
    if unknown or not keys:
        parser.error(f"expected modules among {', '.join(MODULES)} (or --all), got {unknown or 'none'}")
    if args.functions:
        for k in keys:
            MODULES[k] = replace(MODULES[k], functions=tuple(args.functions.split(",")))
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # a kill ends the current child too (_run_child)
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    os.environ.setdefault("ADAPTIVE_MJ_COMPILE_NOTES", "0")
    sys.path.insert(0, str(ROOT))
    if not args.list:
        for heavy in ("numpy", "scipy.stats", "scipy.spatial.transform", "mujoco", "numba", "pytest", "matplotlib",
                      "hypothesis"):  # hypothesis: its pytest plugin, loaded by every run, imports it (1 s)
            try:  # once here, not once per mutant
                importlib.import_module(heavy)
            except ImportError:
                pass
    results = {k: run_module(k, timeout=args.timeout, listing=args.list, verbose=args.verbose) for k in keys}
    if not args.list and len(keys) > 1:
        print("\nmodule             killed+timeout / non-equivalent   score")
        for k, r in results.items():
            if "score" in r:
                counted = r["total"] - r["equivalent"]
                print(f"{k:18} {r['killed'] + r['timeout']:6d} / {counted:<6d}                  "
                      f"{100 * r['score']:5.1f} %")
    return 1 if any(r.get("error") for r in results.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
