"""The breaking-point study's laws and common stressors on a 1-DOF plant of the lecture's sliding law (the heave
vehicle, the 1-DOF arm: their study rows, kinds.StressPlant, name these; plants.study_spec says how they are
called): the adaptive law with no modification; the dead-zone (ε = 3σ_s at the nominal noise); σ-modification and
e-modification (leakage time constant LEAK_TIME on the first parameter, toward the true θ); projection onto
[θ/2, 2θ] for the positive parameters; composite adaptation (when asked, on a row that declares law.composite); and
the two baselines, fixed nominal parameters (the truth) and robust sliding control (K = ROBUST_K_FRACTION of the
actuator limit, Φ = 0.05). Stressors: noise σ_y (y', 10× y) and the sinusoidal disturbance; each kind adds its own.
"""
from __future__ import annotations

from adaptive_mj.laws.sliding import surface_noise_std
from adaptive_mj.plants.study_spec import (LEAK_TIME, Stressor, StudyContext, box_table, sine_disturbance,
                                           theta_table)

ROBUST_K_FRACTION = 0.1  # robust sliding: K = 10 % of the actuator's limit, boundary layer Φ = 0.05


def laws(ctx: StudyContext, composite: bool) -> list[tuple[str, list[str]]]:
    """(law label, overrides) on a 1-DOF plant (the module docstring); every number derived from the context."""
    gamma1 = float(ctx.gamma[0])
    sig_y = ctx.nominal_noise
    assert ctx.lam is not None  # the row's scenario sets law.lam (λ of s's noise)
    sig_s = surface_noise_std(2, ctx.lam, [sig_y, 10 * sig_y])  # the noise of s at the nominal noise
    theta0 = theta_table(ctx.law_names, ctx.theta)
    K = ROBUST_K_FRACTION * float(ctx.plant.ctrl_range[1])
    out = [("adaptive", []),
           ("dead_zone", [f"law.dead_zone={{width={3.0 * sig_s!r}}}"]),
           ("sigma", [f"law.sigma={gamma1 / LEAK_TIME!r}", f"law.theta0={theta0}"]),
           ("e_modification", [f"law.e_modification={gamma1 / (LEAK_TIME * sig_s)!r}", f"law.theta0={theta0}"]),
           ("projection", [f"law.projection={box_table(ctx.law_names, ctx.theta)}"])]
    if composite and ctx.composite is not None:
        out.append(("composite", [f"law.composite={ctx.composite}"]))
    out += [("fixed_nominal", ["law.kind='fixed_nominal'", "law.nominal='model'"]),
            ("robust_sliding", ["law.kind='robust_sliding'", "law.nominal='model'", f"law.K={K!r}",
                                "law.boundary_layer=0.05"])]
    return out


def stressors(ctx: StudyContext) -> list[Stressor]:
    """A 1-DOF plant's common stressors: noise σ_y [output unit] on y (10 σ_y on y') and the sinusoidal
    disturbance (plants.study_spec.sine_disturbance)."""
    return [Stressor("noise σ_y", lambda v: [f"noise.std={{y={v!r}, y_dot={10 * v!r}}}"], 1e-4, 0.1,
                     unit=ctx.output_unit),
            sine_disturbance(ctx)]
