"""Users' own 1-DOF plants, installed as packages: the entry-point group ``adaptive_mj.plants``.

A package registers a ``PlantPlugin`` under a name:

    [project.entry-points."adaptive_mj.plants"]
    my_cart = "my_cart_plant:PLANT"

and a scenario names it: ``plant.kind = "my_cart"`` (with ``plant.model`` to use another
MJCF than the plugin's own, and the plugin's declared keys). The plugin's ``make(model,
params, where)`` turns the compiled model into a plant that satisfies the protocols
``Plant`` and ``FormPlant`` of adaptive_mj.plants.protocol (a ``MujocoPlant`` subclass does, and
is the easy way: it needs the plant's ModelForm and a function reading the true θ from the
compiled model). Every law for 1-DOF plants, built in or a plugin, then runs on it, natively
when it is a ``MujocoPlant`` and its form compiles.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from adaptive_mj.laws.plugin import Param
from adaptive_mj.plants.protocol import Plant
from adaptive_mj.plugins import Installed, discover

ENTRY_POINT_GROUP = "adaptive_mj.plants"


@dataclass(frozen=True)
class PlantPlugin:
    """model: the plugin's MJCF file; make(model, params, where) -> plant (a 1-DOF plant with the
    interface adaptive_mj.plants.protocol.Plant and FormPlant); params: its scenario keys
    (plant.<name>); units: {"output": "m", "control": "N", <param name>: unit} for reports."""

    model: Path
    make: Callable[..., Plant]
    params: tuple[Param, ...] = ()
    units: dict = field(default_factory=dict)
    doc: str = ""

    # -- a plant kind (adaptive_mj.setup.build.plant_kinds) ---------------------------------
    def model_source(self, scn):
        """plant.model's text (the plugin's own MJCF unless the scenario names another)."""
        from adaptive_mj.plants.mujoco_plant import read_model_file

        return read_model_file(scn)

    def from_scenario(self, scn, source):
        from adaptive_mj.plants import BuiltPlant
        from adaptive_mj.plants.mujoco_plant import compile_for_scenario

        model, model_xml = compile_for_scenario(scn, source)
        plant = self.make(model, dict(scn.plant.plugin_params or {}), str(scn.plant.model))
        return BuiltPlant(plant, model_xml)


def installed() -> dict[str, Installed[PlantPlugin]]:
    """Every plant registered under ENTRY_POINT_GROUP, by name (adaptive_mj.plugins.discover)."""
    return discover(ENTRY_POINT_GROUP, PlantPlugin, "plant", lambda p: p.make)
