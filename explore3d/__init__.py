"""explore3d: proprioceptive whole-arm shape exploration.

A blind serial arm wraps around an object again and again; contact is detected from joint
position error alone; link surface points at contact are turned into a mesh by the inverse
convex hull (see ``explore3d.geometry.hull``).  Units are SI everywhere (metres, radians, seconds, kg).

The public API::

    from explore3d import load_object, run, ExploreConfig, inverse_hull, shape_error

The package is built in floors, each importing only from the floors below it (import-linter
contracts in pyproject.toml): ``core`` < ``arm`` < ``geometry`` < ``grasp`` < ``robot`` < ``reconstruction``
< ``feeling`` < ``strategy`` < ``world`` < ``app``; see docs/architecture.md.

The names are imported on first use (PEP 562), so ``import explore3d`` and ``explore3d --help``
load neither numpy nor trimesh nor pybullet.
"""
import importlib

__version__ = "0.1.0"

#: Public name -> the submodule that defines it.
_EXPORTS = {
    "ArmSpec": "arm.spec", "BUILTIN_ARMS": "arm.spec", "load_arm": "arm.urdf", "write_arm_urdf": "arm.urdf",
    "Exploration": "strategy.explore", "ExploreConfig": "strategy.explore", "explore": "world.explore",
    "explore_robots": "strategy.explore", "rough_bound": "strategy.explore",
    "InverseHull": "geometry.hull", "inverse_hull": "geometry.hull",
    "ShapeError": "geometry.metrics", "shape_error": "geometry.metrics",
    "BUILTIN_OBJECTS": "world.objects", "load_object": "world.objects",
    "NoContactError": "app.pipeline", "ReconstructionError": "app.pipeline", "Result": "app.pipeline",
    "reconstruct_exploration": "app.pipeline", "run": "app.pipeline", "write_result": "app.report",
    "ControlConfig": "strategy.encircle", "SimConfig": "core.settings", "SensorConfig": "robot.sensing",
    "Robot": "robot.interface", "RobotLog": "robot.interface", "RecordingRobot": "robot.interface",
    "LogRobot": "robot.interface", "Workcell": "robot.interface", "LogWorkcell": "robot.interface",
    "ContactBand": "feeling.detect", "cached_band": "world.band",
    "ThicknessCalibration": "world.calibration", "calibrate_thickness": "world.calibration",
    "ContactQuality": "world.quality", "contact_quality": "world.quality",
    "OutputConfig": "app.report", "run_and_report": "app.report", "quiet_c_output": "core.quiet",
    "SceneConfig": "core.settings", "SceneSetup": "world.scene", "SceneWatch": "world.scene",
    "settle_scene": "world.scene", "scene_explore_config": "world.scene",
    "GripperSpec": "grasp.gripper", "GraspSet": "grasp.antipodal", "sample_grasps": "grasp.antipodal",
    "execute_grasps": "world.grasping", "grasp_run": "app.grasp",
    "Progress": "app.progress", "RUN_STEPS": "app.progress",
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
