"""The pre-flight check: can the discrete loop of this run be stable at all?

A law's velocity feedback puts a mode at rate μ [1/s] in the closed loop:
  m joints (Slotine–Li and its baselines):  μ(q) = λ_max(M(q)⁻¹ K_D) + max_j Λ_j,
  1-DOF sliding law of order n:             μ = h k_eff / d + (n - 1) λ   (k_eff = k + K/Φ when robust),
  first-order law:                          μ = k,
  a flight law's attitude loop:             μ = max over the principal axes of |roots of J s² + k_Ω s + k_R|,
with M(q) the joint-space inertia (armature included) along the reference and d the plant's true
leading coefficient, both read from the compiled model. One step of length h maps that mode to
  RK4 at the timestep (the law at every stage):     R(-μh), stable while μh < 2.785;
  a control held over h (sampled, Euler, or any    z = 1 - μh, stable while μh < 2;
  one-stage integrator):
  with a delay of D whole periods:                 z^(D+1) - z^D + μh = 0, stable while
                                                   μh < 2 sin(π / (2(2D + 1))).
A flight law's attitude loop with a control delay is checked by its delay margin instead (that first-order bound
passed 14 steps of 2 ms on the bundled quadrotor, whose margin is 23 ms; issue 52): the loop
L(s) = (k_Ω s + k_R) / (J s²) · 1/(τ_m s + 1) about each principal axis of the true inertia J, with the rotors' lag
τ_m from the compiled model, has its crossover ω_c (|L(jω_c)| = 1, found numerically: |L| falls monotonically) and
phase margin PM = π + ∠L(jω_c); its delay margin is PM / ω_c [s]. The run's delay is D·dt plus half a control
period (the zero-order hold's equivalent delay); at or past the smallest margin over the axes the check fails.
The check evaluates the worst μ along the reference (64 samples over the run) against that limit.
Past it, no tuning of the adaptation can help: every step overshoots, torques saturate and the
estimates wind up. Derivation: docs/THEORY.md, "Pre-flight check".

On an arm (a plant with `holding_controls`: the 1-DOF arm, the manipulator) it also checks the
torque: the control that holds the arm still at the reference, g(q_d(t)) (MuJoCo's bias forces at
zero velocity, less the passive ones), at the same 64 samples against the actuators' limits. Past
them no law can follow the reference (a payload typed in grams as kilograms): `gravity` is that
line, a warning, or a refusal under success.preflight = "refuse" (`run --strict`). The model is the
one at t = 0: a later event that changes a mass is not foreseen.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from adaptive_mj.laws.protocol import AirframeFeedback, JointFeedback, Law, SurfaceFeedback
from adaptive_mj.plants.protocol import FormPlant, JointPlant, Plant, has_form, has_joints
from adaptive_mj.setup.success import sampled_positions, sampled_rows
from adaptive_mj.sim.stage import ControlTiming

RK4_REAL_LIMIT = 2.785293563405282  # the RK4 stability region's end on the negative real axis
HOLD_LIMIT = 2.0  # explicit Euler / a zero-order hold: |1 - μh| < 1
SAMPLES = 64  # points of the reference at which M(q) is evaluated


@dataclass(frozen=True)
class Preflight:
    """figure = rate x step against limit; joint: the joint with the largest share K_D,j v_j² of the
    fastest mode v ("" for a 1-DOF plant); fixes: what brings the figure under the limit;
    outside: one line per joint whose reference leaves the joint's range."""

    checked: bool
    figure: float = 0.0
    limit: float = math.inf
    rate: float = 0.0  # μ [1/s]
    step: float = 0.0  # h [s]
    scheme: str = ""
    joint: str = ""
    fixes: tuple[str, ...] = ()
    outside: tuple[str, ...] = ()
    note: str = ""
    plant_lines: tuple[str, ...] = ()  # what the plant itself says cannot work (a quadrotor too heavy to hover)
    # where the figure is the linearised loop's only (a boundary layer's K/Φ, which saturates): why, in words
    linearised: str = ""
    gravity: str = ""  # an arm: the line saying gravity alone at the reference needs more than the motors have
    following: str = ""  # an arm: the line saying following the reference needs far more than the motors have
    # "rate": figure = μh against the step's limit; "delay": figure = the loop's delay [s] against its delay margin
    # [s] (a flight law's attitude loop with a control delay: attitude_margins), rate = the crossover [rad/s]
    measure: str = "rate"
    phase_margin: float = 0.0  # [deg] with measure "delay": the attitude loop's phase margin at its crossover

    @property
    def ok(self) -> bool:
        return not self.checked or self.figure < self.limit

    def figure_text(self) -> str:
        """The figure against its limit, in words: "μh = … > …" or "a delay of … ms ≥ the delay margin … ms"."""
        if self.measure == "delay":
            return (f"a delay of {1e3 * self.figure:.3g} ms {'>=' if self.figure >= self.limit else '<'} the attitude "
                    f"loop's delay margin {1e3 * self.limit:.3g} ms")
        return f"μh = {self.figure:.3g} {'>' if self.figure >= self.limit else '<'} {self.limit:.3g}"

    def line(self) -> str:
        """The one-line warning (empty when ok)."""
        if self.ok:
            return ""
        if self.measure == "delay":
            return (f"pre-flight: {self.joint}: the loop's crossover ω_c = {self.rate:.4g} rad/s with a phase margin "
                    f"of {self.phase_margin:.3g} deg gives a delay margin of {1e3 * self.limit:.3g} ms "
                    f"({self.scheme}); the run's delay of {1e3 * self.figure:.3g} ms is past it: the attitude loop "
                    "cannot be stable. Fixes: " + "; or ".join(self.fixes))
        where = "" if not self.joint else (f"{self.joint}: " if self.joint.startswith("attitude")
                                             else f"joint {self.joint}: ")
        return (f"pre-flight: {where}the loop's fastest mode μ = {self.rate:.4g} 1/s gives μh = {self.figure:.3g} "
                f"at h = {self.step:.3g} s, past the {self.scheme} stability limit {self.limit:.3g}; "
                + (f"the linearised loop cannot be stable ({self.linearised}). " if self.linearised else
                   "the loop cannot be stable. ") + "Fixes: " + "; or ".join(self.fixes))

    def describe(self) -> dict:
        """JSON-ready (the summary's "preflight")."""
        return {"checked": self.checked, "ok": self.ok, "measure": self.measure, "figure": self.figure,
                "limit": self.limit, "phase_margin_deg": self.phase_margin,
                "rate": self.rate, "step": self.step, "scheme": self.scheme, "joint": self.joint,
                "fixes": list(self.fixes), "reference_outside_range": list(self.outside), "note": self.note,
                "plant": list(self.plant_lines), "gravity": self.gravity}


def step_limit(timing: ControlTiming, stages: int) -> tuple[float, float, str]:
    """(h [s], limit on μh, scheme) for the run's control timing and integrator stages."""
    steps = max(1, timing.steps)
    delay_periods = math.ceil(timing.delay / steps) if timing.delay else 0
    h = timing.period
    if delay_periods:
        return h, 2.0 * math.sin(math.pi / (2 * (2 * delay_periods + 1))), \
            f"held control with a delay of {delay_periods} period(s)"
    if timing.sampled:
        return h, HOLD_LIMIT, "zero-order hold at the control period"
    if stages == 4:
        return h, RK4_REAL_LIMIT, "RK4 (the law at every stage)"
    return h, HOLD_LIMIT, "one-stage integrator (explicit in the control)"


def _reference_positions(reference, duration: float, order: int) -> np.ndarray:
    return sampled_positions(reference, duration, SAMPLES, order)


def _worst(M: np.ndarray, kd: np.ndarray) -> tuple[float, np.ndarray]:
    """(μ, v) at the sample of M (N, m, m) where λ_max(M⁻¹K_D) is largest, and its eigenvector
    (K_D v = μ M v), by a Cholesky factor of each M (the symmetric form L⁻¹ K_D L⁻ᵀ); numpy's linalg
    works on the whole stack at once (a 6-joint check: 64 samples in one call each, not 64 calls)."""
    Linv = np.linalg.inv(np.linalg.cholesky(M))
    LinvT = np.swapaxes(Linv, -1, -2)
    A = Linv @ np.diag(kd) @ LinvT
    w, V = np.linalg.eigh(0.5 * (A + np.swapaxes(A, -1, -2)))
    i = int(np.argmax(w[:, -1]))  # the first sample of the largest figure
    return float(w[i, -1]), LinvT[i] @ V[i, :, -1]


def _kd_within(M: np.ndarray, kd: np.ndarray, target: float) -> dict[int, float]:
    """Joint -> lowered K_D such that max over M of λ_max(M⁻¹K_D) <= target, changing only the joints
    above their share: with D = diag(min over the reference of 1/(M⁻¹)_jj) and ρ = max over M of
    λ_max(M⁻¹D) (M⁻¹D has unit diagonal: 1 <= ρ <= m), K_D,j <= target D_jj / ρ on every joint gives
    λ_max(M⁻¹K_D) <= (target/ρ) λ_max(M⁻¹D) <= target (the eigenvalue grows with K_D)."""
    D = np.min(1.0 / np.diagonal(np.linalg.inv(M), axis1=1, axis2=2), axis=0)
    rho = _worst(M, D)[0]
    bound = target * D / rho
    return {j: float(bound[j]) for j in range(len(kd)) if kd[j] > bound[j]}


def _armature_within(M: np.ndarray, kd: np.ndarray, target: float) -> dict[int, float]:
    """Joint -> armature to add [kg m² or kg] so that max over M of λ_max((M + diag(a))⁻¹K_D) <= target.
    MuJoCo adds armature to M's diagonal, and 1/((M + a e_j e_jᵀ)⁻¹)_jj = 1/(M⁻¹)_jj + a exactly, so each
    round raises every joint over its share (_kd_within's bound) by what it lacks, until the figure holds."""
    a = np.zeros(len(kd))
    for _ in range(50):
        Ma = M + np.diag(a)
        if _worst(Ma, kd)[0] <= target:
            return {j: float(a[j]) for j in range(len(kd)) if a[j] > 0}
        D = np.min(1.0 / np.diagonal(np.linalg.inv(Ma), axis1=1, axis2=2), axis=0)
        rho = _worst(Ma, D)[0]
        a += 1.001 * np.maximum(0.0, kd * rho / target - D)
    return {}


def _arm_check(plant: JointPlant, feedback: JointFeedback, q: np.ndarray, h: float, limit: float) -> dict:
    M = plant.mass_matrices(q)
    mu, v = _worst(M, feedback.kd)
    rate = mu + float(feedback.lam.max())
    j = int(np.argmax(feedback.kd * v ** 2))  # the joint with the largest share of the fastest mode
    name = plant.joint_names[j]
    if rate * h < limit:
        return {"rate": rate, "joint": name, "fixes": ()}
    fixes = []
    target = 0.9 * limit / h - float(feedback.lam.max())
    if target > 0:
        table = _kd_within(M, feedback.kd, target)
        kd = np.broadcast_to(np.asarray(feedback.kd, dtype=float), (len(plant.joint_names),))
        # every joint, so that it pastes as --set law.kd={...} (a table must name each joint): the lowered ones
        # and the others at their present gain
        fixes.append("law.kd = {" + ", ".join(f"{name} = {table.get(i, kd[i]):.4g}"
                                              for i, name in enumerate(plant.joint_names)) + "}"
                     + (" (lowered: " + ", ".join(plant.joint_names[i] for i in sorted(table)) + ")" if table else ""))
    fixes.append(f"a timestep or control.period <= {0.9 * limit / rate:.3g} s")
    armature = _armature_within(M, feedback.kd, target) if target > 0 else {}
    if armature:
        fixes.append("more armature on " + ", ".join(f"{plant.joint_names[i]} (+{a:.3g})"
                                                     for i, a in sorted(armature.items())) + " [kg m² or kg]")
    return {"rate": rate, "joint": name, "fixes": tuple(fixes)}


def _one_dof_check(plant: FormPlant, feedback: SurfaceFeedback, h: float, limit: float) -> dict:
    gain, lam_part, what = feedback.effective, feedback.surface_rate, feedback.keys
    form = plant.form
    theta = np.asarray(plant.true_theta(), dtype=float)
    d = float(theta[0]) if form.d_name is not None else 1.0
    x0 = np.asarray(plant.observe(), dtype=float)
    hx = abs(float(form.h(x0)))
    rate = hx * gain / d + lam_part
    fixes = [f"{what} <= {0.9 * (limit / h - lam_part) * d / hx:.3g} (now {gain:.3g})"] if limit / h > lam_part else []
    fixes.append(f"a timestep or control.period <= {0.9 * limit / rate:.3g} s")
    linearised = ""
    if gain > feedback.k:  # robust sliding: K/Φ is the slope inside the boundary layer only; |K sat(s/Φ)| ≤ K
        linearised = (f"inside the boundary layer: K/Φ = {gain - feedback.k:.3g} saturates, the switching term is "
                      f"bounded by K, so the run may still hold; with k alone μh = "
                      f"{(hx * feedback.k / d + lam_part) * h:.3g}")
    return {"rate": rate, "joint": "", "fixes": tuple(fixes), "linearised": linearised}


def check(plant: Plant, law: Law, reference, *, duration: float, timing: ControlTiming) -> Preflight:
    """The pre-flight of one run (before its first step). Reads the plant's inertia along the
    reference; a law that declares no feedback gains (Law.feedback: a plugin, MRAC) is not checked."""
    order = law.order
    h, limit, scheme = step_limit(timing, plant.stages)
    outside = _outside_range(plant, reference, duration, order)
    feedback = law.feedback()
    found: dict | None = None
    if isinstance(feedback, JointFeedback) and has_joints(plant):
        found = _arm_check(plant, feedback, _reference_positions(reference, duration, order), h, limit)
    elif isinstance(feedback, SurfaceFeedback) and has_form(plant):
        found = _one_dof_check(plant, feedback, h, limit)
    elif isinstance(feedback, AirframeFeedback) and hasattr(plant, "airframe"):
        if timing.delay:
            dt = timing.period / max(1, timing.steps)
            return _attitude_delay_check(plant, feedback, timing.delay * dt + 0.5 * timing.period, timing, outside,
                                         gravity_line(plant, reference, duration, order))
        found = _attitude_check(plant, feedback, h, limit)
    lines = getattr(plant, "preflight_lines", None)
    plant_lines = tuple(lines()) if lines is not None else ()
    gravity = gravity_line(plant, reference, duration, order)
    following = "" if gravity else following_line(plant, reference, duration)
    if found is None:
        return Preflight(checked=False, outside=outside, plant_lines=plant_lines, gravity=gravity, following=following,
                         note=f"not checked: the law {type(law).__name__} declares no velocity feedback gain")
    return Preflight(checked=True, figure=found["rate"] * h, limit=limit, rate=found["rate"], step=h,
                     scheme=scheme, joint=found["joint"], fixes=found["fixes"], outside=outside,
                     plant_lines=plant_lines, linearised=found.get("linearised", ""), gravity=gravity,
                     following=following)


FOLLOW_FACTOR = 10.0  # a reference that asks this many times an actuator's limit is beyond any law


def following_line(plant: Plant, reference, duration: float) -> str:
    """One line when following the reference exactly (inverse dynamics along q_d, q̇_d, q̈_d at SAMPLES times:
    `following_controls`) asks more than FOLLOW_FACTOR × an actuator's limit: an amplitude or frequency no arm
    can follow (a moment's saturation is a matter for the run; this is not); "" otherwise, or on a plant
    without that method or limits."""
    follow = getattr(plant, "following_controls", None)
    limits = plant.ctrl_range
    if follow is None or limits is None:
        return ""
    ts = np.linspace(0.0, duration, SAMPLES)
    q, qd, qdd = sampled_rows(reference, duration, SAMPLES, 2)  # each (SAMPLES, m)
    if not (np.isfinite(q).all() and np.isfinite(qd).all() and np.isfinite(qdd).all()):
        return "pre-flight: the reference is not finite over the run: no law can follow it"
    need = np.asarray(follow(q, qd, qdd), dtype=float)
    lim = np.maximum(np.abs(np.asarray(limits[0], dtype=float)), np.abs(np.asarray(limits[1], dtype=float)))
    ratio = np.abs(need) / np.broadcast_to(lim, need.shape)
    i, j = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
    if not ratio[i, j] > FOLLOW_FACTOR:
        return ""
    name = plant.joint_names[j] if getattr(plant, "joint_names", ()) else "the joint"
    return (f"pre-flight: following the reference asks {need[i, j]:.3g} N m of {name} at t = {ts[i]:.3g} s "
            f"(inverse dynamics along q_d, q̇_d = {qd[i, j]:.3g}, q̈_d = {qdd[i, j]:.3g}), {ratio[i, j]:.3g}× its "
            f"actuator's limit {lim[j]:.4g}: no law can follow this reference (check its amplitudes and frequencies)")


def gravity_line(plant: Plant, reference, duration: float, order: int) -> str:
    """One line when holding the arm still at the reference (gravity alone: `holding_controls`, sampled at
    SAMPLES times over the run) needs more than an actuator's limit (ctrl_range), naming the joint that
    needs the most (relative to its limit), when, how much, and how many joints are short; "" when every
    joint's motor can hold it, or the plant has no such method or no limit."""
    holding = getattr(plant, "holding_controls", None)
    limits = plant.ctrl_range
    if holding is None or limits is None:
        return ""
    q = _reference_positions(reference, duration, order)
    need = np.asarray(holding(q), dtype=float).reshape(len(q), -1)
    m = need.shape[1]
    lo = np.broadcast_to(np.asarray(limits[0], dtype=float), (m,))
    hi = np.broadcast_to(np.asarray(limits[1], dtype=float), (m,))
    with np.errstate(divide="ignore", invalid="ignore"):
        over = np.where(need > hi, need / np.where(hi > 0, hi, np.nan), 0.0)  # past the limit, by this factor
        under = np.where(need < lo, need / np.where(lo < 0, lo, np.nan), 0.0)
    ratio = np.nan_to_num(np.maximum(over, under), nan=np.inf)
    short = (need > hi) | (need < lo)
    if not short.any():
        return ""
    i, j = np.unravel_index(int(np.argmax(np.where(short, ratio, -1.0))), need.shape)
    unit = " N m"  # the torque (the 1-DOF arm: over its gear); a slide joint's force in N
    name = f"joint {plant.joint_names[j]}" if plant.joint_names else "the joint"
    others = int(short.any(axis=0).sum()) - 1
    t = float(np.linspace(0.0, duration, SAMPLES)[i])
    return (f"pre-flight: gravity alone at the reference needs {need[i, j]:.4g}{unit} on {name} at t = {t:.3g} s "
            f"(q_d = {q[i, j]:.4g}), past its actuator's limit [{lo[j]:.4g}, {hi[j]:.4g}]{unit}"
            + (" (N on a slide joint)" if plant.joint_names else "")
            + (f", and {others} other joint(s) short" if others > 0 else "")
            + ": no law can hold the arm still there, and where the reference dwells the run saturates (a pre-flight"
            " figure from the model at t = 0, not the run's verdict; is a mass too large, e.g. plant.payload_mass in"
            " grams as kg?)")


def _attitude_check(plant: Plant, feedback: AirframeFeedback, h: float, limit: float) -> dict:
    """The attitude loop J ë + k_Ω ė + k_R e = 0 about each principal axis of the true inertia (the plant's θ: m,
    then Jxx, Jyy, Jzz, Jxy, Jxz, Jyz): its fastest root's modulus is μ."""
    th = np.asarray(plant.true_theta(), dtype=float)
    xx, yy, zz, xy, xz, yz = th[1:7]
    J = np.linalg.eigvalsh(np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]))
    roots = [np.roots([j, feedback.kW, feedback.kR]) for j in J]
    fastest = int(np.argmax([np.abs(r).max() for r in roots]))
    rate = float(np.abs(roots[fastest]).max())
    axis = f"{J[fastest]:.3g} kg m²"
    fixes = (f"law.kW <= {0.9 * limit / h * float(J.min()):.3g} (now {feedback.kW:.3g}) with law.kR as it is",
             f"a timestep or control.period <= {0.9 * limit / rate:.3g} s")
    return {"rate": rate, "joint": f"attitude (about the principal axis of inertia {axis})",
            "fixes": fixes if rate * h >= limit else ()}


def loop_margins(J: float, kR: float, kW: float, tau: float = 0.0) -> tuple[float, float, float]:
    """(ω_c [rad/s], PM [rad], delay margin [s]) of the attitude loop about one axis: the plant 1/(J s²) (J [kg m²])
    under the PD moment k_R + k_Ω s (k_R [N m/rad], k_Ω [N m s/rad]) through a rotor lag 1/(τ s + 1) (τ [s], 0:
    none), L(s) = (k_Ω s + k_R)/(J s² (τ s + 1)). |L(jω)| falls monotonically in ω, so its crossover is found by
    bisection on log ω (to 1e-12 relative); PM = atan2(k_Ω ω_c, k_R) − atan(τ ω_c) (π + ∠L), delay margin PM/ω_c."""
    def gain(w: float) -> float:
        return math.hypot(kW * w, kR) / (J * w * w * math.hypot(1.0, tau * w))

    lo, hi = 1e-6, 1e9
    for _ in range(200):
        mid = math.sqrt(lo * hi)
        if gain(mid) > 1.0:
            lo = mid
        else:
            hi = mid
        if hi / lo - 1.0 < 1e-12:
            break
    wc = math.sqrt(lo * hi)
    pm = math.atan2(kW * wc, kR) - math.atan(tau * wc)
    return wc, pm, pm / wc


def attitude_margins(plant: Plant, feedback: AirframeFeedback) -> list[tuple[float, float, float, float]]:
    """(J [kg m²], ω_c [rad/s], PM [rad], delay margin [s]) about each principal axis of the plant's true inertia
    (θ's Jxx .. Jyz, from the compiled model), with its rotors' lag τ_m (plant.rotor_lag(), 0 where it has none)
    and the law's k_R, k_Ω: loop_margins."""
    th = np.asarray(plant.true_theta(), dtype=float)
    xx, yy, zz, xy, xz, yz = th[1:7]
    J = np.linalg.eigvalsh(np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]))
    lag = getattr(plant, "rotor_lag", None)
    tau = float(lag()) if lag is not None else 0.0
    return [(float(j), *loop_margins(float(j), feedback.kR, feedback.kW, tau)) for j in J]


def _attitude_delay_check(plant: Plant, feedback: AirframeFeedback, delay: float, timing: ControlTiming,
                          outside: tuple[str, ...], gravity: str) -> Preflight:
    """The pre-flight of a flight law's run with a control delay [s] (the steps' and half the hold's): the delay
    against the attitude loop's smallest delay margin over the principal axes (attitude_margins)."""
    margins = attitude_margins(plant, feedback)
    J, wc, pm, margin = min(margins, key=lambda row: row[3])
    dt = timing.period / max(1, timing.steps)
    lines = getattr(plant, "preflight_lines", None)
    fixes = (f"simulation.control_delay <= {max(0, math.ceil((margin - 0.5 * timing.period) / dt) - 1)} steps",
             f"law.kR, law.kW lower (a slower attitude loop: crossover now {wc:.3g} rad/s)")
    return Preflight(checked=True, figure=delay, limit=margin, rate=wc, step=dt,
                     scheme="the attitude loop L = (k_Ω s + k_R)/(J s² (τ_m s + 1))",
                     joint=f"attitude (about the principal axis of inertia {J:.3g} kg m²)",
                     fixes=fixes if delay >= margin else (), outside=outside,
                     plant_lines=tuple(lines()) if lines is not None else (), gravity=gravity, measure="delay",
                     phase_margin=math.degrees(pm))


def _outside_range(plant: Plant, reference, duration: float, order: int) -> tuple[str, ...]:
    """One line per limited joint whose reference position leaves [lo, hi] during the run."""
    limits = plant.joint_limits
    if limits is None:
        return ()
    q = _reference_positions(reference, duration, order)
    ts = np.linspace(0.0, duration, SAMPLES)
    names = plant.joint_names or ("the joint",)
    out = []
    for j, (lo, hi) in enumerate(np.atleast_2d(limits)):
        below, above = q[:, j] < lo, q[:, j] > hi
        if below.any() or above.any():
            i = int(np.argmax(below | above))
            by = float(max(lo - q[:, j].min(), q[:, j].max() - hi))
            out.append(f"the reference leaves {names[j]}'s range [{lo:.4g}, {hi:.4g}] at t = {ts[i]:.3g} s "
                       f"(by up to {by:.3g})")
    return tuple(out)
