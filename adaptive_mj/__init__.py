"""adaptive-mj: the lecture's adaptive laws on MuJoCo physics."""
from adaptive_mj.sim.loop import Event, run
from adaptive_mj.trajectory import Trajectory

__version__ = "0.1.0"
__all__ = ["run", "Event", "Trajectory", "__version__"]
