"""explore3d: proprioceptive whole-arm shape exploration.

A blind serial arm wraps around an object again and again; contact is detected from joint
position error alone; link surface points at contact are turned into a mesh by the inverse
convex hull (see ``explore3d.hull``).  Units are SI everywhere (metres, radians, seconds, kg).

The public API::

    from explore3d import load_object, run, ExploreConfig, inverse_hull, shape_error

The names are imported on first use (PEP 562), so ``import explore3d`` and ``explore3d --help``
load neither numpy nor trimesh nor pybullet.
"""
import importlib
import sys
import types

__version__ = "0.1.0"

#: Public name -> the submodule that defines it.
_EXPORTS = {
    "ArmSpec": "arm", "BUILTIN_ARMS": "arm", "load_arm": "arm", "write_arm_urdf": "urdf",
    "Exploration": "explore", "ExploreConfig": "explore", "explore": "explore", "rough_bound": "explore",
    "InverseHull": "hull", "inverse_hull": "hull",
    "ShapeError": "metrics", "shape_error": "metrics",
    "BUILTIN_OBJECTS": "objects", "load_object": "objects",
    "NoContactError": "pipeline", "ReconstructionError": "pipeline", "Result": "pipeline",
    "reconstruct_exploration": "pipeline", "run": "pipeline", "write_result": "pipeline",
    "ControlConfig": "encircle", "SimConfig": "sim", "SensorConfig": "sensing",
    "Robot": "robot", "RobotLog": "robot", "RecordingRobot": "robot", "LogRobot": "robot",
    "ContactBand": "detect", "cached_band": "band",
    "ThicknessCalibration": "calibration", "calibrate_thickness": "calibration",
    "ContactQuality": "quality", "contact_quality": "quality",
    "OutputConfig": "pipeline", "run_and_report": "pipeline", "quiet_c_output": "_quiet",
    "SceneConfig": "scene", "SceneSetup": "scene", "SceneWatch": "scene", "settle_scene": "scene",
    "scene_explore_config": "scene",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'explore3d' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))


class _Package(types.ModuleType):
    """The package's module type: importing the submodule ``explore3d.explore`` must not replace
    the public function ``explore3d.explore`` (Python sets a package attribute for every loaded
    submodule); the submodule stays available as ``sys.modules["explore3d.explore"]``."""

    def __setattr__(self, name, value):
        if name == "explore" and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
