"""Payload files (plant.payload, and the payload of a payload_swap event): where a name is
looked for, and what a file must be before anything runs.

A name without a "/" that does not end in ".xml" is a bundled payload, models/payloads/<name>.xml.
Any other name is a path: absolute, or relative, then looked for next to the scenario file first
and in the current directory second (as plant.model is found next to the scenario).

`check_text` refuses, each in one line naming the file: an empty file, binary data, XML that is not
well formed, XML whose root is not <mujoco>, a number attribute that is NaN or infinite (MuJoCo
would replace a NaN mass by one computed from the density, silently), a negative mass, a file that
MuJoCo cannot compile on its own, and a payload whose bodies weigh 0 kg in all (nothing to attach,
and plant.payload_mass could not scale it). `swap_inertial` adds what a payload_swap needs: a body
named "body" of finite mass > 0.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from adaptive_mj.data import PAYLOADS
from adaptive_mj.errors import ModelError

SWAP_BODY = "body"  # the body of a payload file whose inertial a payload_swap takes

#: key prefix of a payload_swap file's text in a run's ModelSource.assets (and so in its log): a log
#: re-simulates its events from what it embeds, from any folder
ASSET_PREFIX = "payload_swap:"


def is_bundled(name: str) -> bool:
    return "/" not in name and "\\" not in name and not name.endswith(".xml")


def candidates(name: str, base_dir: Path) -> tuple[Path, ...]:
    """Where a payload named `name` is looked for, in order."""
    if is_bundled(name):
        return (PAYLOADS / f"{name}.xml",)
    p = Path(name).expanduser()
    if p.is_absolute():
        return (p,)
    here, there = base_dir / p, Path.cwd() / p
    return (here,) if here.resolve() == there.resolve() else (here, there)


def locate(name: str, paths: tuple[Path, ...], *, where: str, key: str) -> Path:
    """The first of `paths` that is a file, or a one-line ModelError saying where it was looked for."""
    for p in paths:
        if p.is_file():
            return p
    if is_bundled(name):
        choices = sorted(p.stem for p in PAYLOADS.glob("*.xml"))
        raise ModelError(f"{where}: {key} {name!r} is not a bundled payload ({', '.join(choices)}); give one of "
                         "those or a path to an MJCF file ending in .xml")
    if len(paths) == 1:
        raise ModelError(f"{where}: {key} {name!r} not found ({paths[0]})")
    raise ModelError(f"{where}: {key} {name!r} not found next to the scenario ({paths[0]}) nor in the current "
                     f"directory ({paths[1]})")


def read(path: Path) -> str:
    """The file's text; an unreadable, empty or binary file is a one-line ModelError."""
    from adaptive_mj.plants.mujoco_plant import read_mjcf

    return read_mjcf(path, "payload")


def _numbers_finite(root: ET.Element, path: Path) -> None:
    for el in root.iter():
        for attr, value in el.attrib.items():
            for token in value.split():
                try:
                    v = float(token)
                except ValueError:
                    continue
                if not math.isfinite(v):
                    why = " (MuJoCo would replace a NaN mass by one computed from the density, silently)" \
                        if math.isnan(v) and attr == "mass" else ""
                    raise ModelError(f"{path}: <{el.tag}> {attr}={value!r}: not a finite number{why}")
                if attr == "mass" and v < 0:
                    raise ModelError(f"{path}: <{el.tag}> mass={value!r}: a mass must be >= 0 kg")


def check_text(text: str, path: Path, *, on_disk: bool):
    """The payload MJCF compiled on its own (an MjModel), after the checks of the module docstring.
    on_disk: `text` is the file at `path` (compiled from the file, so its relative asset paths
    resolve); else it is compiled from the text alone (a log's embedded copy)."""
    import mujoco

    from adaptive_mj.plants.mujoco_plant import with_userdata

    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise ModelError(f"{path}: not well-formed XML ({exc}), expected an MJCF model (<mujoco>...)") from None
    if root.tag != "mujoco":
        raise ModelError(f"{path}: not an MJCF model: the root element is <{root.tag}>, expected <mujoco>")
    _numbers_finite(root, path)
    try:
        spec = mujoco.MjSpec.from_file(str(path)) if on_disk else mujoco.MjSpec.from_string(text)
        model = with_userdata(spec).compile()
    except ValueError as exc:
        raise ModelError(f"{path}: MuJoCo could not compile the payload: {str(exc).strip()}") from None
    total = float(np.sum(model.body_mass[1:]))
    if not math.isfinite(total) or total <= 0:
        raise ModelError(f"{path}: the payload has no mass (its bodies weigh {total:g} kg in all); give its geoms a "
                         "mass > 0")
    return model


def swap_inertial(model, path: Path) -> dict:
    """mass [kg], ipos (3,), iquat (4,), inertia (3,) of the payload's body "body", for a payload_swap."""
    import mujoco

    b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, SWAP_BODY)
    if b < 0:
        names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, i) for i in range(1, model.nbody)]
        raise ModelError(f"{path}: a payload_swap takes the inertial of the body named {SWAP_BODY!r}, which this "
                         f"payload does not have (bodies: {names})")
    out = {"mass": float(model.body_mass[b]), "ipos": model.body_ipos[b].copy(),
           "iquat": model.body_iquat[b].copy(), "inertia": model.body_inertia[b].copy()}
    if not (math.isfinite(out["mass"]) and out["mass"] > 0):
        raise ModelError(f"{path}: the body {SWAP_BODY!r} has mass {out['mass']:g} kg; a payload_swap needs a "
                         "finite mass > 0 (give its geoms a mass)")
    if not all(np.all(np.isfinite(out[k])) for k in ("ipos", "iquat", "inertia")):
        raise ModelError(f"{path}: the body {SWAP_BODY!r} has a non-finite centre of mass or inertia")
    return out
