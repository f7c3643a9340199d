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
  Form.AIRFRAME    a free rigid body flown by rotor thrusts along its z axis: x = [p; v; φ; Ω] (4, 3), the
                   rotors' allocation [f, M] = A thrusts and their limits, gravity (adaptive_mj.plants.quadrotor;
                   the laws of adaptive_mj.laws.geometric and laws.l1)

A plant kind declares the forms it offers in its own module (adaptive_mj.plants.kinds). A law offered to a
plant none of whose forms it serves is refused in one line that names the forms on both sides and the laws
that would serve (`refusal`). No mujoco here.

Each built-in law kind declares itself beside its code (``KIND = register(LawKind(...))`` at the bottom of
adaptive_mj/laws/sliding.py, first_order.py, mrac.py, slotine_li.py): its name, the forms it serves, whether
it adapts, a line of doc, its scenario keys as data (adaptive_mj.keys.Key), the reader of those keys (a
`Reader`: the [law] table -> adaptive_mj.specs.LawSpec) and its builder (a `Builder`: a `BuildContext`, which
adaptive_mj.setup.build implements, -> the law object). `built_in` finds them by construction: every module
of the adaptive_mj.laws package is imported once and what registered is the set of built-in kinds (as
adaptive_mj.plants.kinds does for plants). The keys every law shares (law.order, law.gamma, law.dead_zone,
the estimates, the robust modifications, law.saturation) are read by adaptive_mj.laws.law_keys; a kind
lists which of them it takes. A new law kind touches no table elsewhere.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Protocol

from adaptive_mj.plugins import scan_built_in

if TYPE_CHECKING:
    import numpy as np

    from adaptive_mj.form import ModelForm
    from adaptive_mj.keys import Key, Table
    from adaptive_mj.laws.common import DeadZone, Modification
    from adaptive_mj.laws.protocol import Law
    from adaptive_mj.specs import LawSpec, PlantSpec, Scenario


class Form(enum.Enum):
    """How a law sees a plant (see the module docstring)."""

    MODEL = "model"
    RIGID_BODY = "rigid_body"
    MRAC_STATE = "mrac_state"
    AIRFRAME = "airframe"

    @property
    def text(self) -> str:
        """The form in words, for messages and `list --laws`."""
        return FORM_TEXT[self]


FORM_TEXT = {
    Form.MODEL: "the 1-DOF model form d y^(n) = f + phi'p + h u",
    Form.RIGID_BODY: "the multi-joint rigid-body form (regressor Y, M(q))",
    Form.MRAC_STATE: "the MRAC state form (x, the reference model's state)",
    Form.AIRFRAME: "the airframe form (a free body's p, v, attitude, rate; rotor allocation)",
}


#: a kind's key reader: (its [law] table, law.kind, the plant's spec, the order n of the plant's output
#: dynamics) -> the checked LawSpec; the loader has read law.kind (and refused a plant whose forms the kind
#: does not serve), the reader reads every other key it takes and calls t.finish() (unknown keys refused)
Reader = Callable[["Table", str, "PlantSpec", int], "LawSpec"]
#: a kind's builder: the scenario and the plant as the law sees them -> the law object
#: (adaptive_mj.laws.protocol.Law); a ValueError becomes a one-line ScenarioError
Builder = Callable[["BuildContext"], "Law"]


@dataclass(frozen=True)
class LawKind:
    """A law kind: its name, the forms it serves, whether it adapts, a line of doc, and where it comes
    from ("built in", or "plugin from <distribution> <version> (source <sha256[:12]>)").

    A built-in kind also declares: keys, its scenario keys under [law] (law.kind and the shared keys it
    takes included, as `read` reads them; tests/test_law_kinds.py keeps the two equal); read, its key
    reader; build, its builder; plant_kinds, when not empty the only plant kinds it serves, which then take
    no other built-in law (first_order_adaptive on the first-order plant); module, where it is declared;
    filters_key, the key that turns on its filters (integrated in the stage states: continuous control only)."""

    name: str
    forms: frozenset[Form]
    adaptive: bool
    doc: str
    origin: str = "built in"
    keys: tuple[Key, ...] = ()
    read: Reader | None = None
    build: Builder | None = None
    plant_kinds: frozenset[str] = frozenset()
    module: str = ""
    # the key that gives the law its filters, as the refusal of a sampled-data controller names it (a law plugin
    # and a built-in kind that declares none: law.composite)
    filters_key: str = "law.composite"
    # a bundled scenario and the --set overrides that run this kind (tests load it to check the keys the reader
    # takes against `keys` and docs/SCENARIOS.md): a new kind names its own, no test table changes
    example: tuple[str, tuple[str, ...]] | None = None


@dataclass(frozen=True)
class RigidBody:
    """A multi-joint plant as a law of Form.RIGID_BODY sees it: regressor, the plant's Y(q, v, w, a) (with
    τ_known, M(q) and gravity: adaptive_mj.plants.manipulator); names (n_theta,) its parameters in π order;
    m, the number of joints; joint_names (m,)."""

    regressor: Any
    names: tuple[str, ...]
    m: int
    joint_names: tuple[str, ...]


@dataclass(frozen=True)
class MracState:
    """A plant as a law of Form.MRAC_STATE sees it: order n; b, the control's gain the law is designed for
    (its sign is known to the law); psi(x) -> (k,) the matched nonlinear terms and psi_names (k,) (None and
    (): none); names (n_theta,) the law's gains in θ order."""

    order: int
    b: float
    psi: Callable[[np.ndarray], np.ndarray] | None
    psi_names: tuple[str, ...]
    names: tuple[str, ...]


@dataclass(frozen=True)
class AirframeView:
    """A flying body as a law of Form.AIRFRAME sees it: allocation (4, 4), [f, M_x, M_y, M_z] = allocation @
    thrusts [N, N m] (the rotors' layout and yaw coefficients from the compiled model); thrust_max (4,) [N];
    gravity g [m/s²] (along −z); names (n_theta,) the plant's parameters in θ order (m, J, d)."""

    allocation: Any
    thrust_max: Any
    gravity: float
    names: tuple[str, ...]


class BuildContext(Protocol):
    """What a law kind's builder sees (adaptive_mj.setup.build implements it): the scenario, its LawSpec, the
    shared modifications built from the shared keys, and the plant through the form the law serves (ask only
    for a form the kind declares: the scenario loader checked that the plant offers it)."""

    @property
    def scenario(self) -> Scenario: ...

    @property
    def law(self) -> LawSpec: ...

    @property
    def modification(self) -> Modification | None:
        """law.sigma, law.e_modification, law.theta0 and law.projection, or None when all are off."""
        ...

    def model_form(self) -> ModelForm:
        """Form.MODEL: the 1-DOF plant's d y⁽ⁿ⁾ = f + φᵀp + h u."""
        ...

    def rigid_body(self) -> RigidBody:
        """Form.RIGID_BODY: the multi-joint plant's regressor, parameter names and joints."""
        ...

    def mrac_state(self) -> MracState:
        """Form.MRAC_STATE: the plant's order, control gain and matched nonlinear terms."""
        ...

    def airframe(self) -> AirframeView:
        """Form.AIRFRAME: the flying body's rotor allocation, thrust limits and gravity."""
        ...

    def gamma(self, names: tuple[str, ...]) -> np.ndarray | float | None:
        """law.gamma: a number, (n_theta,) in the order of `names` (a table), or None when absent."""
        ...

    def dead_zone(self) -> DeadZone | None:
        """law.dead_zone with its width [the tested signal's unit] resolved (width_in_noise_std), or None."""
        ...

    def saturation(self) -> tuple[Any, Any]:
        """The actuator limits (lo, hi) law.saturation = "freeze" reads: floats [N or N m] on a 1-DOF plant,
        (m,) [N m] on an arm; raises a ScenarioError when the plant has none."""
        ...

    def per_joint(self, key: str, value: float | dict[str, float]) -> np.ndarray:
        """(m,) a value for every joint of a multi-joint plant: a number, or {joint: value} giving each."""
        ...

    def named(self, key: str, values: dict[str, float], names: tuple[str, ...]) -> np.ndarray:
        """(len(names),) a table {parameter: value} that must give `names` in that order (key: for the
        message)."""
        ...


_BUILT_IN: dict[str, LawKind] = {}
_SCANNED = False

#: the order the built-in kinds are listed in (a kind missing here comes last, in the order it registers)
ORDER = ("sliding_adaptive", "first_order_adaptive", "fixed_nominal", "robust_sliding", "mrac", "slotine_li",
         "computed_torque", "pd_gravity", "geometric", "geometric_adaptive", "l1_geometric")


def register(kind: LawKind) -> LawKind:
    """Called by a law module at import: adds its kind to the built-in registry (a name once)."""
    if kind.name in _BUILT_IN and _BUILT_IN[kind.name] != kind:
        raise ValueError(f"law kind {kind.name!r} registered twice ({_BUILT_IN[kind.name].module}, {kind.module})")
    _BUILT_IN[kind.name] = kind
    return kind


def built_in() -> dict[str, LawKind]:
    """The built-in law kinds by name, in ORDER (every module of the package is imported once: a kind is
    found by its own module, not by a list); a kind registered later (a test's) joins at the end."""
    global _SCANNED
    if not _SCANNED:
        scan_built_in("adaptive_mj.laws", _BUILT_IN, ORDER)
        _SCANNED = True
    return dict(_BUILT_IN)


#: the built-in law kinds by name (built_in(), read afresh at each use: `from adaptive_mj.laws.kinds import
#: BUILT_IN` or `kinds.BUILT_IN`); their keys: docs/SCENARIOS.md, checked by tests/test_law_kinds.py
BUILT_IN: dict[str, LawKind]


def __getattr__(name: str) -> Any:
    if name == "BUILT_IN":
        return built_in()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def table_keys() -> tuple[str, ...]:
    """The [law] keys of the built-in kinds whose value may be a table (a sub-table of another name may be
    a law kind's scoped keys: adaptive_mj.setup.scenario._scoped_law_keys), in the order first declared."""
    names: dict[str, None] = {}
    for kind in built_in().values():
        names.update((k.name, None) for k in kind.keys if k.takes_table)
    return tuple(names)


def misfit(law: LawKind, plant_kind: str) -> str | None:
    """None when `law` may run on plant_kind as far as the built-in kinds' plant_kinds go; else what law.kind
    must be, in words ("'first_order_adaptive' exactly when plant.kind = 'first_order'")."""
    for k in built_in().values():
        if k.plant_kinds and (k.name == law.name) != (plant_kind in k.plant_kinds):
            return f"{k.name!r} exactly when plant.kind = " + " or ".join(repr(p) for p in sorted(k.plant_kinds))
    return None


def plugin_kind(name: str, installed) -> LawKind:
    """The LawKind of an installed law plugin (adaptive_mj.plugins.Installed of a LawPlugin or JointLawPlugin)."""
    plugin = installed.plugin
    return LawKind(name, frozenset(Form(f) for f in plugin.forms), bool(plugin.adapts), plugin.doc,
                   f"plugin from {installed.distribution} {installed.version} (source {installed.source_sha256[:12]})")


def all_kinds(*, plugins: bool = True) -> dict[str, LawKind]:
    """Every law kind by name: the built-in ones, then the installed plugins (when `plugins`)."""
    kinds = built_in()
    if plugins:
        from adaptive_mj.laws.plugin import installed

        for name, inst in sorted(installed().items()):
            kinds.setdefault(name, plugin_kind(name, inst))
    return kinds


def serving(plant_kind: str, offered: frozenset[Form], kinds: dict[str, LawKind]) -> list[str]:
    """The names of the kinds in `kinds` that serve a form in `offered` (the forms plant_kind offers:
    adaptive_mj.plants.kinds); a built-in kind with plant_kinds only on those, which take no other built-in
    law (`misfit`)."""
    out = []
    for name, k in kinds.items():
        if not k.forms & offered:
            continue
        if k.origin == "built in" and misfit(k, plant_kind) is not None:
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
