"""Every configuration field is validated at construction: a one-line ValueError naming the class,
the field, what is expected (with its unit) and what was given."""
import subprocess
import sys

import pytest

from explore3d.strategy.encircle import ControlConfig
from explore3d.strategy.explore import ExploreConfig
from explore3d.robot.sensing import SensorConfig
from explore3d.core.settings import SimConfig

BAD = [
    (ControlConfig, dict(speed=0.0), "ControlConfig.speed.*rad/s"),
    (ControlConfig, dict(tip_speed=-1.0), "ControlConfig.tip_speed.*m/s"),
    (ControlConfig, dict(band_factor=0.5), "ControlConfig.band_factor.*>= 1"),
    (ControlConfig, dict(ramp_time=float("nan")), "ControlConfig.ramp_time.*s"),
    (ControlConfig, dict(limit_margin=-0.1), "ControlConfig.limit_margin.*rad"),
    (ControlConfig, dict(sweep_torque_margin=-1), "ControlConfig.sweep_torque_margin.*N m"),
    (ControlConfig, dict(settle_steps=1.5), "ControlConfig.settle_steps.*integer"),
    (ControlConfig, dict(rereference_held="yes"), "ControlConfig.rereference_held"),
    (SimConfig, dict(timestep=0.1), "SimConfig.timestep.*s"),
    (SimConfig, dict(position_gain=0), "SimConfig.position_gain"),
    (SimConfig, dict(friction=-0.2), "SimConfig.friction"),
    (SimConfig, dict(collision_margin=0.5), "SimConfig.collision_margin.*m"),
    (SimConfig, dict(gravity=(0, 0)), "SimConfig.gravity.*m/s"),
    (SimConfig, dict(solver="pgs"), "SimConfig.solver"),
    (SensorConfig, dict(torque_resolution_nm=-1e-3), "SensorConfig.torque_resolution_nm"),
    (ExploreConfig, dict(base_step=0.0), "ExploreConfig.base_step.*rad"),
    (ExploreConfig, dict(clearance=-0.01), "ExploreConfig.clearance.*m"),
    (ExploreConfig, dict(face_offset=float("inf")), "ExploreConfig.face_offset.*m"),
    (ExploreConfig, dict(faces=("top",)), "ExploreConfig.faces"),
    (ExploreConfig, dict(control={"speed": 1.0}), "ExploreConfig.control must be a ControlConfig"),
    (ExploreConfig, dict(sensors=None), "ExploreConfig.sensors must be a SensorConfig"),
]


@pytest.mark.parametrize("cls,kwargs,match", BAD, ids=[f"{c.__name__}-{next(iter(k))}" for c, k, _ in BAD])
def test_bad_field_is_a_one_line_error(cls, kwargs, match):
    with pytest.raises(ValueError, match=match) as e:
        cls(**kwargs)
    assert "\n" not in str(e.value) and "got" in str(e.value)


def test_defaults_are_valid_and_faces_become_a_tuple():
    for cls in (ControlConfig, SimConfig, SensorConfig, ExploreConfig):
        cls()
    assert ExploreConfig(faces=["inner", "outer"]).faces == ("inner", "outer")


def test_geometry_modules_import_neither_the_urdf_nor_the_simulation():
    """kinematics, hull, metrics, directions, detect and the robot interface are pure: importing them
    loads no URDF writer, no simulation module and no pybullet."""
    code = ("import sys; import explore3d.arm.kinematics, explore3d.geometry.hull, explore3d.geometry.metrics, explore3d.geometry.directions, "
            "explore3d.feeling.detect, explore3d.robot.interface, explore3d.robot.sensing; "
            "bad = [m for m in ('explore3d.arm.urdf', 'explore3d.world.sim', 'pybullet') if m in sys.modules]; print(bad)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_global_cfm_validated_and_off_by_default():
    """SimConfig.global_cfm: None (PyBullet's 0) by default, so the band keys of the factory
    settings do not change; a negative value is refused naming the field."""
    assert SimConfig().global_cfm is None
    assert SimConfig(global_cfm=1e-6).global_cfm == 1e-6
    with pytest.raises(ValueError, match="SimConfig.global_cfm"):
        SimConfig(global_cfm=-1.0)
