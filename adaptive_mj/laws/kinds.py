"""The law kinds and the plant forms they serve: one registry that the scenario loader, `list --laws`
and the error messages read (built-in kinds and installed plugins through the same path).

A plant offers one or more *forms* (how a law sees it), a law kind serves one or more:

  Form.MODEL       the 1-DOF model form of the lecture, d y⁽ⁿ⁾ = f(x) + φ(x)ᵀp + h(x) u (adaptive_mj.form.ModelForm):
                   the heave vehicle, the 1-DOF arm, the ship, the first-order plant, wing rock, plant plugins
  Form.RIGID_BODY  a multi-joint rigid-body tree, M(q) q̈ + C(q, q̇) q̇ + g(q) + D q̇ = τ, through its regressor
                   Y(q, v, w, a) π + τ_known = M(q) a + C(q, v) w + g(q) + D v evaluated where the law asks,
                   with M(q) for V (adaptive_mj.plants.manipulator)
  Form.MRAC_STATE  the state form of model-reference adaptive control: x, the reference model's state and the
                   matched nonlinear terms (adaptive_mj.laws.mrac): the linear plants and wing rock

A plant kind declares the forms it offers in its own module (adaptive_mj.plants.kinds). A law offered to a
plant none of whose forms it serves is refused in one line that names the forms on both sides and the laws
that would serve (`refusal`). No mujoco here.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass


class Form(enum.Enum):
    """How a law sees a plant (see the module docstring)."""

    MODEL = "model"
    RIGID_BODY = "rigid_body"
    MRAC_STATE = "mrac_state"

    @property
    def text(self) -> str:
        """The form in words, for messages and `list --laws`."""
        return FORM_TEXT[self]


FORM_TEXT = {
    Form.MODEL: "the 1-DOF model form d y^(n) = f + phi'p + h u",
    Form.RIGID_BODY: "the multi-joint rigid-body form (regressor Y, M(q))",
    Form.MRAC_STATE: "the MRAC state form (x, the reference model's state)",
}


@dataclass(frozen=True)
class LawKind:
    """A law kind: its name, the forms it serves, whether it adapts, a line of doc, and where it comes
    from ("built in", or "plugin from <distribution> <version> (source <sha256[:12]>)")."""

    name: str
    forms: frozenset[Form]
    adaptive: bool
    doc: str
    origin: str = "built in"


#: The built-in law kinds (their keys: docs/SCENARIOS.md, checked by adaptive_mj.setup.scenario).
BUILT_IN = {k.name: k for k in (
    LawKind("sliding_adaptive", frozenset({Form.MODEL}), True,
            "the lecture's sliding-surface adaptive law of order n (with its modifications)"),
    LawKind("first_order_adaptive", frozenset({Form.MODEL}), True,
            "the lecture's first-order adaptive law (plant.kind = 'first_order' only)"),
    LawKind("fixed_nominal", frozenset({Form.MODEL}), False,
            "the sliding law with the estimates frozen at law.nominal (baseline)"),
    LawKind("robust_sliding", frozenset({Form.MODEL}), False,
            "sliding control with a boundary layer, K sat(s/phi), no adaptation (baseline)"),
    LawKind("mrac", frozenset({Form.MRAC_STATE}), True,
            "model-reference adaptive control (Lyapunov rule or the MIT rule)"),
    LawKind("slotine_li", frozenset({Form.RIGID_BODY}), True,
            "Slotine-Li adaptive control of a manipulator, tau = Y pi_hat + K_D s"),
    LawKind("computed_torque", frozenset({Form.RIGID_BODY}), False,
            "computed torque at the nominal parameters (baseline)"),
    LawKind("pd_gravity", frozenset({Form.RIGID_BODY}), False,
            "PD plus gravity compensation at the nominal parameters (baseline)"),
)}

def plugin_kind(name: str, installed) -> LawKind:
    """The LawKind of an installed law plugin (adaptive_mj.plugins.Installed of a LawPlugin or JointLawPlugin)."""
    plugin = installed.plugin
    return LawKind(name, frozenset(Form(f) for f in plugin.forms), bool(plugin.adapts), plugin.doc,
                   f"plugin from {installed.distribution} {installed.version} (source {installed.source_sha256[:12]})")


def all_kinds(*, plugins: bool = True) -> dict[str, LawKind]:
    """Every law kind by name: the built-in ones, then the installed plugins (when `plugins`)."""
    kinds = dict(BUILT_IN)
    if plugins:
        from adaptive_mj.laws.plugin import installed

        for name, inst in sorted(installed().items()):
            kinds.setdefault(name, plugin_kind(name, inst))
    return kinds


def serving(plant_kind: str, offered: frozenset[Form], kinds: dict[str, LawKind]) -> list[str]:
    """The names of the kinds in `kinds` that serve a form in `offered` (the forms plant_kind offers:
    adaptive_mj.plants.kinds); first_order_adaptive only on the first-order plant, which takes no other
    built-in law of the model form."""
    out = []
    for name, k in kinds.items():
        if not k.forms & offered:
            continue
        if (name == "first_order_adaptive") != (plant_kind == "first_order") and k.origin == "built in":
            continue
        out.append(name)
    return out


def refusal(law: LawKind, plant_kind: str, offered: frozenset[Form], kinds: dict[str, LawKind]) -> str | None:
    """None when `law` serves a form in `offered` (what plant_kind offers); else the one-line reason (without
    the file), naming the laws of `kinds` that would serve."""
    if law.forms & offered:
        return None
    serves = " and ".join(f.text for f in sorted(law.forms, key=lambda f: f.value))
    offers = " and ".join(f.text for f in sorted(offered, key=lambda f: f.value))
    alternatives = ", ".join(serving(plant_kind, offered, kinds)) or "none installed"
    return (f"law.kind = {law.name!r} serves {serves}; plant.kind = {plant_kind!r} offers {offers} "
            f"(laws that serve it: {alternatives})")
