"""The bundled models, payloads and scenarios, found through importlib.resources.

In the repository they live at its top level (models/, models/payloads/, scenarios/), where the README,
the docs and the scenarios name them; adaptive_mj/data/models and adaptive_mj/data/scenarios are
links to those folders, and a wheel (or a non-editable `pip install .`) holds copies of them as
package data ([tool.setuptools.package-data] in pyproject.toml). Either way the folders below are
real directories: MuJoCo compiles a model from a file path. The paths are resolved, so a message
names models/x.xml in a checkout and site-packages/adaptive_mj/data/models/x.xml in an install.
"""
from __future__ import annotations

from importlib.resources import files
from pathlib import Path


def _folder(name: str) -> Path:
    # files() of a package installed as a directory (every pip install; not a zipped import) is a Path
    return Path(str(files(__name__).joinpath(name))).resolve()


MODELS = _folder("models")            # the MJCF plants: heave_vehicle.xml, pendulum_arm.xml, ur5e_arm.xml
PAYLOADS = MODELS / "payloads"        # the payloads attached to an arm (plant.payload = "sphere", ...)
SCENARIOS = _folder("scenarios")      # the bundled scenario files (adaptive-mj list)
