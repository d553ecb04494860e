"""Executing planned grasps on the true object in PyBullet (evaluation only: it builds and reads
a world of its own; the exploration never calls it).

One new world per grasp (deterministic: the same grasp gives the same outcome): a static table
whose top is the plane ``z = table_z``, the true object resting on it at the pose it was given
(a free body of its convex parts, mass ``density`` times its volume), and a floating parallel-jaw
gripper (:class:`~explore3d.grasp.gripper.GripperSpec`) whose palm a fixed constraint drives.  The
gripper starts ``approach_m`` back along its approach, open to the grasp's opening, moves onto the
grasp pose, closes with ``grip_force_n`` per finger, lifts ``lift_m`` straight up, shakes
horizontally and holds.  The object is held when its centre of mass is still at least half the
lift above where it started, ``shake_s + hold_s`` (2 s) after the lift ended.

Frames: world frame = the frame the grasps and the truth are given in, z up, metres; PyBullet
quaternions are (x, y, z, w).
"""
from __future__ import annotations

import enum
import math
import os
import tempfile
from dataclasses import dataclass

import numpy as np

from explore3d.core.interrupt import deferred_signals
from explore3d.core.quiet import quiet_c_output
from explore3d.core.validate import check_field
from explore3d.grasp.antipodal import GraspSet
from explore3d.grasp.gripper import GripperSpec
from explore3d.world.parts import convex_parts, parts_obj_text
from explore3d.world.sim import _pose_from_T


class Outcome(enum.Enum):
    """How an executed grasp ended."""

    HELD = "held"  #: lifted and still held at the end
    DROPPED = "dropped"  #: lifted at least half the lift, then lost (in the shake or the hold)
    MISSED = "missed"  #: never lifted half the lift (missed, slipped or pushed the object away)


@dataclass(frozen=True)
class ExecutionConfig:
    """How a grasp is executed (SI units).

    Attributes:
        density: the object's density, kg/m^3 (500: a light wood or a plastic part, as the table
            scene's).
        table_friction, rolling_friction_m, spinning_friction_m: between the object and the
            table (the table scene's values: docs/scene.md).
        settle_s: passive time before the gripper moves, s (the support's contact manifold gathers
            its corners).
        approach_s, close_s, lift_s: durations of the approach, the closing and the lift, s.
        lift_m: how high the object is lifted, m.
        shake_s, shake_amplitude_m, shake_hz: a horizontal circle of this radius and frequency
            after the lift (peak acceleration 1.6 m/s^2 at 10 mm and 2 Hz).
        hold_s: still time after the shake, s.
        timestep: the physics step, s.
    """

    density: float = 500.0
    table_friction: float = 0.5
    rolling_friction_m: float = 0.001
    spinning_friction_m: float = 0.0005
    settle_s: float = 0.25
    approach_s: float = 0.5
    close_s: float = 0.5
    lift_s: float = 1.0
    lift_m: float = 0.1
    shake_s: float = 1.0
    shake_amplitude_m: float = 0.01
    shake_hz: float = 2.0
    hold_s: float = 1.0
    timestep: float = 1.0 / 240.0

    def __post_init__(self):
        for name in ("density", "approach_s", "close_s", "lift_s", "lift_m", "timestep"):
            check_field(self, name, lo=0.0, strict=True)
        for name in ("table_friction", "rolling_friction_m", "spinning_friction_m", "settle_s", "shake_s",
                     "shake_amplitude_m", "shake_hz", "hold_s"):
            check_field(self, name, lo=0.0)


@dataclass(frozen=True)
class GraspExecution:
    """One executed grasp: its ``outcome``, the object's final and largest rise of its centre of
    mass, m, and ``push_m``: how far the object's centre of mass moved from the start of the
    approach to the end of the closing, m.  A grasp planned where the true surface is closes
    both fingers on it at once and barely moves the object; one planned on a surface that is not
    there pushes it with the first finger that touches (or knocks it with the approach)."""

    outcome: Outcome
    rise_m: float
    max_rise_m: float
    push_m: float = 0.0

    @property
    def held(self) -> bool:
        return self.outcome is Outcome.HELD


class _GraspWorld:
    """A PyBullet client with the table, the object and the gripper (built per grasp)."""

    def __init__(self, obj_path: str, com: np.ndarray, mass: float, table_z: float, T_grasp: np.ndarray,
                 opening: float, gripper: GripperSpec, config: ExecutionConfig):
        with quiet_c_output():
            import pybullet  # start-up: kept out of explore3d --help's (and loaded quietly: its banner)
            from pybullet_utils import bullet_client

            with deferred_signals():  # a Ctrl-C inside would leave a half-made client whose __del__ complains
                self.p = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
        p = self.p
        p.setGravity(0.0, 0.0, -9.81)
        p.setTimeStep(config.timestep)
        p.setPhysicsEngineParameter(deterministicOverlappingPairs=1)
        table = p.createMultiBody(0.0, p.createCollisionShape(pybullet.GEOM_BOX, halfExtents=[1.0, 1.0, 0.05]),
                                  basePosition=[float(com[0]), float(com[1]), table_z - 0.05])
        # PyBullet multiplies the two bodies' coefficients; the object's lateral friction 1 leaves the others'
        p.changeDynamics(table, -1, lateralFriction=config.table_friction, rollingFriction=config.rolling_friction_m,
                         spinningFriction=config.spinning_friction_m, restitution=0.0)
        self.object = p.createMultiBody(mass, p.createCollisionShape(pybullet.GEOM_MESH, fileName=obj_path),
                                        basePosition=[float(x) for x in com])
        p.changeDynamics(self.object, -1, lateralFriction=1.0, restitution=0.0)

        finger_l, finger_r, palm = gripper.boxes(opening, swept=False)  # -x finger, +x finger, palm
        shape = lambda box: p.createCollisionShape(pybullet.GEOM_BOX, halfExtents=box[1].tolist(),  # noqa: E731
                                                   collisionFramePosition=[0.0, 0.0, float(box[0][2])])
        self.T_grasp = np.asarray(T_grasp, float)
        T_start = self.T_grasp.copy()
        T_start[:3, 3] -= gripper.approach_m * self.T_grasp[:3, 2]
        pos, quat = _pose_from_T(T_start)
        self.gripper = p.createMultiBody(
            gripper.palm_mass_kg, shape(palm), basePosition=pos, baseOrientation=quat,
            linkMasses=[gripper.finger_mass_kg] * 2, linkCollisionShapeIndices=[shape(finger_l), shape(finger_r)],
            linkVisualShapeIndices=[-1, -1], linkPositions=[[0.0, 0.0, 0.0]] * 2,
            linkOrientations=[[0.0, 0.0, 0.0, 1.0]] * 2, linkInertialFramePositions=[[0.0, 0.0, 0.0]] * 2,
            linkInertialFrameOrientations=[[0.0, 0.0, 0.0, 1.0]] * 2, linkParentIndices=[0, 0],
            linkJointTypes=[pybullet.JOINT_PRISMATIC] * 2, linkJointAxis=[[1.0, 0.0, 0.0]] * 2)
        self.open_x = np.array([float(finger_l[0][0]), float(finger_r[0][0])])  # the fingers' centres, grasp x
        for j in (0, 1):
            p.resetJointState(self.gripper, j, self.open_x[j])
            p.changeDynamics(self.gripper, j, lateralFriction=gripper.friction,
                             spinningFriction=gripper.spin_friction_m)
        p.changeDynamics(self.gripper, -1, lateralFriction=gripper.friction)
        # The fingers move as a parallel gripper's linkage moves them, mirrored (q0 = -q1): without the
        # coupling the pair, each pressing with its own force limit, slides sideways under any load
        # along the closing axis.
        gear = p.createConstraint(self.gripper, 0, self.gripper, 1, pybullet.JOINT_GEAR, [1, 0, 0], [0, 0, 0],
                                  [0, 0, 0])
        p.changeConstraint(gear, gearRatio=1.0, maxForce=1000.0)
        self.constraint = p.createConstraint(self.gripper, -1, -1, -1, pybullet.JOINT_FIXED, [0, 0, 0], [0, 0, 0],
                                             childFramePosition=pos, childFrameOrientation=quat)
        self.quat = quat
        self.pybullet = pybullet

    def hold_open(self) -> None:
        for j in (0, 1):
            self.p.setJointMotorControl2(self.gripper, j, self.pybullet.POSITION_CONTROL,
                                         targetPosition=float(self.open_x[j]), force=200.0)

    def close_fingers(self, force: float) -> None:
        for j, v in ((0, 0.1), (1, -0.1)):  # m/s towards each other, pressing with at most ``force``
            self.p.setJointMotorControl2(self.gripper, j, self.pybullet.VELOCITY_CONTROL, targetVelocity=v,
                                         force=float(force))

    def move_to(self, position) -> None:
        self.p.changeConstraint(self.constraint, [float(x) for x in position], self.quat, maxForce=2000.0)

    def object_position(self) -> np.ndarray:
        """(3,) the object's centre of mass, world frame, m (evaluation: the world's own state)."""
        return np.array(self.p.getBasePositionAndOrientation(self.object)[0], dtype=np.float64)

    def object_z(self) -> float:
        return float(self.object_position()[2])


def execute_grasps(truth, grasps: GraspSet, gripper: GripperSpec = GripperSpec(), table_z: float | None = None,
                   config: ExecutionConfig = ExecutionConfig()) -> list[GraspExecution]:
    """Execute every grasp of ``grasps`` (world frame; only their poses and openings are used) on
    ``truth`` (closed trimesh, world frame, metres) resting on a table whose top is ``table_z``
    (m; default the truth's lowest point), each in a new world (module docstring); one
    :class:`GraspExecution` per grasp, in order."""
    if not isinstance(gripper, GripperSpec) or not isinstance(config, ExecutionConfig):
        raise TypeError("gripper must be a GripperSpec and config an ExecutionConfig")
    table_z = float(truth.bounds[0, 2]) if table_z is None else float(table_z)
    com = np.asarray(truth.center_mass, float)
    mass = float(config.density * truth.volume)
    parts = [(V - com, F) for V, F in convex_parts(truth)]
    fd, path = tempfile.mkstemp(suffix=".obj", prefix="explore3d_grasp_object_")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(parts_obj_text(parts))
        return [_execute(path, com, mass, table_z, grasps.poses[i], float(grasps.openings[i]), gripper, config)
                for i in range(len(grasps))]
    finally:
        os.unlink(path)


def _execute(obj_path, com, mass, table_z, T_grasp, opening, gripper, config) -> GraspExecution:
    world = _GraspWorld(obj_path, com, mass, table_z, T_grasp, opening, gripper, config)
    p, dt = world.p, config.timestep
    try:
        world.hold_open()
        steps = lambda s: max(1, int(math.ceil(s / dt)))  # noqa: E731
        for _ in range(steps(config.settle_s)):
            p.stepSimulation()
        p0 = world.object_position()
        z0 = float(p0[2])
        start = world.T_grasp[:3, 3] - gripper.approach_m * world.T_grasp[:3, 2]
        n = steps(config.approach_s)
        for k in range(1, n + 1):
            world.move_to(start + (k / n) * (world.T_grasp[:3, 3] - start))
            p.stepSimulation()
        world.close_fingers(gripper.grip_force_n)
        for _ in range(steps(config.close_s)):
            p.stepSimulation()
        push = float(np.linalg.norm(world.object_position() - p0))
        top, best = world.T_grasp[:3, 3].copy(), 0.0
        n = steps(config.lift_s)
        for k in range(1, n + 1):
            world.move_to(top + [0.0, 0.0, config.lift_m * k / n])
            p.stepSimulation()
            best = max(best, world.object_z() - z0)
        top[2] += config.lift_m
        n = steps(config.shake_s)
        for k in range(1, n + 1):
            ph = 2.0 * math.pi * config.shake_hz * k * dt
            a = config.shake_amplitude_m
            world.move_to(top + [a * math.sin(ph), a * (1.0 - math.cos(ph)), 0.0])
            p.stepSimulation()
            best = max(best, world.object_z() - z0)
        world.move_to(top)
        for _ in range(steps(config.hold_s)):
            p.stepSimulation()
        rise = world.object_z() - z0
    finally:
        p.disconnect()
    enough = 0.5 * config.lift_m
    outcome = Outcome.HELD if rise >= enough else Outcome.DROPPED if best >= enough else Outcome.MISSED
    return GraspExecution(outcome=outcome, rise_m=float(rise), max_rise_m=float(max(best, rise)), push_m=push)
