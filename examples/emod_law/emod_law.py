"""An adaptive-mj law plugin: the lecture's sliding law of order 2 with e-modification.

    s = ỹ' + λ ỹ,  ṡ_r = y_d'' + λ ỹ'
    u = (d̂ ṡ_r − f − φᵀp̂ + k s) / h
    d̂' = (ṡ_r s − ν |s| d̂) / γ_d,   p̂_j' = (−φ_j s − ν |s| p̂_j) / γ_p

The law is a plain function over arrays and floats (no numpy calls that allocate, no
Python objects), so adaptive-mj compiles it into MuJoCo's native control callback.
"""
from adaptive_mj.laws.plugin import LawPlugin, Param
from adaptive_mj.laws.protocol import SurfaceFeedback


def emod(x, ref, theta, phi, f, h, params, rate):
    lam, k, gamma_d, gamma_p, nu = params[0], params[1], params[2], params[3], params[4]
    e0 = ref[0] - x[0]
    e1 = ref[1] - x[1]
    s = e1 + lam * e0
    s_r_dot = ref[2] + lam * e1
    acc = theta[0] * s_r_dot - f + k * s
    for j in range(phi.shape[0]):
        acc -= phi[j] * theta[j + 1]
    leak = nu * abs(s)
    rate[0] = (s_r_dot * s - leak * theta[0]) / gamma_d
    for j in range(phi.shape[0]):
        rate[j + 1] = (-phi[j] * s - leak * theta[j + 1]) / gamma_p
    return acc / h, s


def feedback(params):
    """Its velocity feedback for the pre-flight check: k on s = ỹ' + λ ỹ, the surface adding λ to the loop's
    fastest mode (the built-in sliding law's, for order 2)."""
    return SurfaceFeedback(k=params["k"], lam=params["lambda"], effective=params["k"], surface_rate=params["lambda"],
                           keys="law.k")


LAW = LawPlugin(
    law=emod,
    params=(Param("lambda", gt=0.0, unit="1/s", doc="surface slope λ"),
            Param("k", ge=0.0, unit="N s/m", doc="gain on s"),
            Param("gamma_d", gt=0.0, doc="adaptation stiffness of d̂"),
            Param("gamma_p", gt=0.0, doc="adaptation stiffness of p̂"),
            Param("nu", default=0.0, ge=0.0, doc="e-modification leakage ν")),
    doc="order-2 sliding law with e-modification (leakage ν|s|θ̂)",
    orders=(2,),  # it reads ref[2] and x[1]: a plant of order 2
    feedback=feedback,  # the pre-flight check warns of a sampled loop past its stability limit
)
