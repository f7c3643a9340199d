"""Plants: the only code that touches MjModel/MjData (plus the analytic twin).

Every plant offers the same small interface to the loop, the protocol
``adaptive_mj.plants.protocol.Plant`` (its module docstring lists every member):
  order, names  the order n of the output dynamics and the names of θ
  dt          physics step [s]
  time        current simulation time [s]
  ctrl_range  (lo, hi) actuator limits in control units, or None
  observe()   (n,) true state [y, y', ...]
  true_theta() (n_theta,) true parameters, ordered as names
  controlled_by(policy)  context manager: policy(t, x) -> u runs at every
                         evaluation of the dynamics (MuJoCo's control callback)
  step()      advance one physics step
and the 1-DOF plants their ModelForm (``form``: the structure the law assumes).

Each plant kind (heave, arm, first_order in twin.py, manipulator) builds itself
from its scenario section: its module has ``model_source(scn) -> ModelSource |
None`` (the MJCF text to compile) and ``from_scenario(scn, source) -> BuiltPlant``.
``adaptive_mj.setup.build`` looks the kind up in the registry (``plants/kinds.py``)
and calls those two; it has no branch per kind. The kind's scenario keys are its own
too (``PlantKind.keys`` and ``.reader``; shared ones in ``plants/plant_keys.py``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable

if TYPE_CHECKING:
    from adaptive_mj.plants.protocol import Plant


@dataclass(frozen=True)
class ModelSource:
    """The exact MJCF text compiled for a run, and its assets (name -> bytes)."""

    xml: str
    assets: dict


@dataclass(frozen=True)
class BuiltPlant:
    """What a plant kind's ``from_scenario(scn, source)`` returns.

    plant: the plant (interface above); model_xml: the compiled model as MJCF
    (the log's model.xml), None for an analytic twin; notes: edits made to the
    model for the run (servo_to_torque), shown on the terminal and logged.
    """

    plant: Plant
    model_xml: str | None = None
    notes: tuple[str, ...] = ()


@dataclass(frozen=True)
class Event:
    """At time t [s] (first step with t_k >= t), call apply(plant). label: text for logs.
    apply calls what its plant kind offers beyond the Plant protocol (set_body_mass on the arms,
    set_fluid_density on the heave vehicle), which the scenario has checked."""

    t: float
    label: str
    apply: Callable[[Any], None]


def plant_order(plant: Plant) -> int:
    """n: the order of the plant's output dynamics (2 for a manipulator: x = [q; q̇])."""
    return plant.order
