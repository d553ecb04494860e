"""explore3d: proprioceptive whole-arm shape exploration.

A blind serial arm wraps around an object again and again; contact is detected from joint
position error alone; link surface points at contact are turned into a mesh by the inverse
convex hull (see ``explore3d.hull``).  Units are SI everywhere (metres, radians, seconds, kg).

The public API::

    from explore3d import load_object, run, ExploreConfig, inverse_hull, shape_error
"""
__version__ = "0.1.0"

from .arm import BUILTIN_ARMS, ArmSpec, load_arm, write_arm_urdf
from .explore import Exploration, ExploreConfig, explore, rough_bound
from .hull import InverseHull, inverse_hull
from .metrics import ShapeError, shape_error
from .objects import BUILTIN_OBJECTS, load_object
from .pipeline import NoContactError, Result, reconstruct_exploration, run

__all__ = [
    "ArmSpec", "BUILTIN_ARMS", "BUILTIN_OBJECTS", "Exploration", "ExploreConfig", "InverseHull", "NoContactError",
    "Result", "ShapeError", "explore", "inverse_hull", "load_arm", "load_object", "reconstruct_exploration",
    "rough_bound", "run", "shape_error", "write_arm_urdf",
]
