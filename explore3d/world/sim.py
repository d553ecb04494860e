"""One PyBullet world: the arm, optionally a static object, gravity.  A thin stateful wrapper.

:class:`ArmSimulation` (the world) owns its own PyBullet DIRECT client (no global client), so
several can live in one process and in parallel processes.  It holds no geometry logic.

The exploration never sees the world: it gets a :class:`SimRobot` (:meth:`ArmSimulation.robot`),
the :class:`~explore3d.robot.interface.Robot` interface of the simulated arm, which reads the joints through
:mod:`explore3d.robot.sensing` and holds no client.  The world's client (:attr:`ArmSimulation.client`)
is for the evaluation layer and rendering only.

Quaternions passed to PyBullet are (x, y, z, w).
"""
from __future__ import annotations

import functools
import os
import sys
import tempfile
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from explore3d.arm.spec import ArmSpec
from explore3d.arm.urdf import arm_urdf
from explore3d.core.interrupt import deferred_signals
from explore3d.core.quiet import quiet_c_output
from explore3d.core.settings import SimConfig
from explore3d.core.validate import check_field
from explore3d.robot.interface import JointCommand, JointReading, Robot, Workcell
from explore3d.robot.sensing import SensorConfig, Sensors
from explore3d.world.parts import parts_obj_text


def mass_scales(n: int, mass_error: float, seed: int) -> np.ndarray:
    """(n,) factors of the simulated links' masses over the model's: ``1 + e``, ``e`` uniform in
    ``[-mass_error, mass_error]``, seeded (ones when ``mass_error`` is 0)."""
    if mass_error == 0:
        return np.ones(n)
    rng = np.random.default_rng([int(seed), 7919])
    return 1.0 + rng.uniform(-mass_error, mass_error, n)


def _pose_from_T(T) -> tuple[list, list]:
    """(position (3,), quaternion (x, y, z, w)) of a (4, 4) homogeneous transform."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise ValueError(f"a base transform must be a finite (4, 4) matrix; got shape {T.shape}")
    return T[:3, 3].tolist(), Rotation.from_matrix(T[:3, :3]).as_quat().tolist()


#: Passive steps a new world with a resting object runs before the arm moves.  PyBullet's contact
#: manifold between the object and the table starts with a single point (the settled pose is
#: carried over from another world, its manifold is not) and gathers the support's corners over
#: the next steps (measured: 4 points after 36-55 steps for the cube, cylinder, box and cone).  With one
#: point at the face's centre nothing but spinning friction resists a turn: the table cube turned
#: 1 degree in the first wrap, under 0.002 N m it spun 1-19 degrees in 5 s.
MANIFOLD_STEPS = 120


class ArmSimulation(Workcell):
    """The arm (fixed base) and an optional static triangle-mesh object in one DIRECT client: a
    simulated :class:`~explore3d.robot.interface.Workcell`.

    Args:
        spec: the arm.
        vertices, faces: the object as a (v, 3) float array (metres, world frame) and (f, 3) int
            array, loaded as a static concave mesh (``GEOM_FORCE_CONCAVE_TRIMESH``, mass 0); or
            None for free space.
        config: physics settings.
    """

    def __init__(self, spec: ArmSpec, vertices=None, faces=None, config: SimConfig = SimConfig(), scene=None):
        self.spec = spec
        self.config = config
        with quiet_c_output():  # PyBullet's C-level banners: build time, argv[0]=, solver switch
            import pybullet  # start-up: kept out of explore3d --help's (and loaded quietly: its banner)
            from pybullet_utils import bullet_client

            with deferred_signals():  # a Ctrl-C inside would leave a half-made client whose __del__ complains
                self._p = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
            p = self._p
            p.setGravity(*config.gravity)
            p.setTimeStep(config.timestep)
            if config.solver == "dantzig":
                p.setPhysicsEngineParameter(constraintSolverType=pybullet.CONSTRAINT_SOLVER_LCP_DANTZIG)
            if config.global_cfm is not None:
                p.setPhysicsEngineParameter(globalCFM=float(config.global_cfm))
        p.setPhysicsEngineParameter(deterministicOverlappingPairs=1)
        fd, path = tempfile.mkstemp(suffix=".urdf", prefix=f"explore3d_{spec.name}_")
        try:
            with os.fdopen(fd, "w") as fh:
                fh.write(arm_urdf(spec))
            flags = pybullet.URDF_USE_SELF_COLLISION if config.self_collision else 0
            self.arm = p.loadURDF(path, useFixedBase=True, flags=flags)
        finally:
            os.unlink(path)
        self.joints = list(range(spec.n_links))
        # Switch off the default velocity motors so POSITION_CONTROL alone drives the joints.
        p.setJointMotorControlArray(self.arm, self.joints, pybullet.VELOCITY_CONTROL, forces=[0.0] * len(self.joints))
        self.object = None
        self.table = None
        margin = {} if config.collision_margin is None else {"collisionMargin": float(config.collision_margin)}
        link_friction = config.friction
        if scene is not None:
            sc = scene.config
            link_friction = config.friction if sc.friction is None else sc.friction
            if scene.parts:  # resting: a free body of convex parts, built by the scene
                self.object = self._resting_object(scene, margin)
                if sc.contact_erp is not None:
                    p.setPhysicsEngineParameter(contactERP=float(sc.contact_erp))
            else:  # fixed where the truth is
                vertices, faces = scene.truth.vertices, scene.truth.faces
            if scene.table_z is not None:
                self.table = self._table(scene)
        if vertices is not None and self.object is None:
            v = np.asarray(vertices, dtype=np.float64)
            f = np.asarray(faces, dtype=np.int64)
            col = p.createCollisionShape(
                pybullet.GEOM_MESH, vertices=v.tolist(), indices=f.ravel().tolist(),
                flags=pybullet.GEOM_FORCE_CONCAVE_TRIMESH,
            )
            self.object = p.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=col)
            # in a scene the links' coefficient is the pair's (PyBullet multiplies the two bodies')
            p.changeDynamics(self.object, -1, lateralFriction=config.friction if scene is None else 1.0,
                             restitution=0.0, **margin)
        for j in [-1] + self.joints:
            # Two calls: PyBullet ignores the whole changeDynamics call on a link of a multibody when it
            # carries collisionMargin (measured: lateralFriction unchanged); the margin alone stays a
            # no-op there (the links keep PyBullet's 1 mm), the friction and restitution take.
            p.changeDynamics(self.arm, j, lateralFriction=link_friction, restitution=0.0)
            if margin:
                p.changeDynamics(self.arm, j, **margin)
        if config.mass_error > 0:  # the real arm differs from its model
            for j, f in zip(self.joints, mass_scales(len(self.joints), config.mass_error, config.mass_seed)):
                info = p.getDynamicsInfo(self.arm, j)
                p.changeDynamics(self.arm, j, mass=info[0] * float(f),
                                 localInertiaDiagonal=[float(x) * float(f) for x in info[2]])
        self.persistent = scene is not None and scene.config.persistent
        self._pc = pybullet.POSITION_CONTROL
        self._world_frame = pybullet.WORLD_FRAME
        # The per-step calls bound to this client once: BulletClient's attribute lookup costs
        # more than the calls themselves in a 24-link loop (measured: a third of the loop).
        cid = p._client
        self._step_sim = functools.partial(pybullet.stepSimulation, physicsClientId=cid)
        self._joint_states = functools.partial(pybullet.getJointStates, physicsClientId=cid)
        self._motor_array = functools.partial(pybullet.setJointMotorControlArray, physicsClientId=cid)
        self._external_torque = functools.partial(pybullet.applyExternalTorque, physicsClientId=cid)
        #: the stated rolling and spinning friction of a resting object on the table, applied by the
        #: world on the Dantzig solver (which drops them: :mod:`explore3d.world.support`); None otherwise
        self._resistance = None
        if scene is not None and scene.parts and self.table is not None and config.solver == "dantzig" and (
                scene.config.rolling_friction_m > 0 or scene.config.spinning_friction_m > 0):
            from explore3d.world.support import SupportFriction  # start-up: it loads pybullet

            info = p.getDynamicsInfo(self.object, -1)
            self._resistance = SupportFriction(cid, self.object, self.table, float(scene.config.rolling_friction_m),
                                               float(scene.config.spinning_friction_m), float(info[0]),
                                               float(min(info[2])), float(scene.table_z), config.timestep)
        if scene is not None and scene.parts:  # the arm waits far from the scene until a motion starts
            p.resetBasePositionAndOrientation(self.arm, [50.0, 50.0, 50.0], [0.0, 0.0, 0.0, 1.0])
            for _ in range(MANIFOLD_STEPS):  # the object's support gathers its corners (not counted in steps)
                self._physics_step()
        self.steps = 0
        #: evaluation only: called with the world after every commanded step (never by the exploration)
        self.step_observer = None
        self._torques = np.array(spec.joint_torques())
        self._sent = None
        self._axis = np.array([0.0, 0.0, 1.0])
        self._state = p.saveState()

    def robot(self, sensors: SensorConfig = SensorConfig(), wrap: int | None = None) -> "SimRobot":
        """The :class:`~explore3d.robot.interface.Robot` interface of the simulated arm, read through
        ``sensors``; for wrap number ``wrap`` its noise is seeded with ``(0, wrap)``
        (:meth:`SimRobot.reseed`; None: not reseeded)."""
        robot = SimRobot(self, sensors)
        if wrap is not None:
            robot.reseed((0, wrap))
        return robot

    # --- the robot's actuators and sensors (used by SimRobot only) --------------------------------
    def _start(self, T_world_base, q0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Restore the initial physics state (every motion starts from the same state whatever ran
        before), put the base at ``T_world_base`` and the joints at rest at ``q0``; hold there.
        Returns the exact (q, dq, tau)."""
        if not self.persistent:  # a persistent world keeps the object where the last motion left it
            self._p.restoreState(self._state)
        self._axis = np.asarray(T_world_base, dtype=np.float64)[:3, 2].copy()  # every joint axis is the base z axis
        pos, quat = _pose_from_T(T_world_base)
        self._p.resetBasePositionAndOrientation(self.arm, pos, quat)
        q0 = np.asarray(q0, dtype=np.float64)
        for j, qj in zip(self.joints, q0):
            self._p.resetJointState(self.arm, j, float(qj), 0.0)
        self._sent = None
        n = len(self.joints)
        self._send(q0, np.zeros(n), self._torques)
        return q0.copy(), np.zeros(n), np.zeros(n)

    def _send(self, q_ref, dq_ref, limits) -> None:
        c = self.config
        n = len(self.joints)
        self._motor_array(
            self.arm, self.joints, self._pc, targetPositions=list(q_ref), targetVelocities=list(dq_ref),
            forces=list(limits), positionGains=[c.position_gain] * n, velocityGains=[c.velocity_gain] * n,
        )
        self._sent = (np.array(q_ref), np.array(dq_ref), np.array(limits))

    def _apply_feed_forward(self, tau_ff: np.ndarray) -> None:
        # PyBullet's position motors take no feed-forward torque.  A motor torque tau_j on joint j
        # is an internal pair: +tau_j on link j and -tau_j on its parent about the joint axis.  So
        # link j receives the external torque (tau_j - tau_{j+1}) about the (common) joint axis:
        # the same generalised forces, exactly.  Cleared by PyBullet after every step.
        net = tau_ff.copy()
        net[:-1] -= tau_ff[1:]
        ax, ay, az = self._axis.tolist()
        arm, frame, torque = self.arm, self._world_frame, self._external_torque
        for j, t in enumerate(net.tolist()):  # Python floats: the same products as numpy's, less overhead
            if t != 0.0:
                torque(arm, j, (t * ax, t * ay, t * az), frame)

    def _step(self, command: JointCommand) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Send ``command``, advance one timestep; return the exact joint angles (n,), rad, velocities
        (n,), rad/s, and motor torques (n,), N m (the position loop's plus the feed-forward)."""
        limits = np.minimum(command.torque_limit, self._torques)
        s = self._sent
        if s is None or not (np.array_equal(command.q_ref, s[0]) and np.array_equal(command.dq_ref, s[1])
                             and np.array_equal(limits, s[2])):
            self._send(command.q_ref, command.dq_ref, limits)
        tau_ff = np.asarray(command.tau_ff, dtype=np.float64)
        if tau_ff.any():
            self._apply_feed_forward(tau_ff)
        self._physics_step()
        self.steps += 1
        if self.step_observer is not None:  # the evaluation's (explore3d.world.scene.SceneWatch)
            self.step_observer(self)
        q, dq, _, tau = zip(*self._joint_states(self.arm, self.joints))
        return np.array(q, dtype=np.float64), np.array(dq, dtype=np.float64), np.array(tau, dtype=np.float64) + tau_ff

    # --- the scene's bodies (built once) ------------------------------------------------------------
    def _resting_object(self, scene, margin) -> int:
        """A free body of the scene's convex parts at its settled pose, mass ``scene.mass_kg``."""
        pybullet = sys.modules["pybullet"]  # imported quietly by __init__
        p = self._p
        fd, path = tempfile.mkstemp(suffix=".obj", prefix="explore3d_object_")
        try:
            with os.fdopen(fd, "w") as fh:
                fh.write(parts_obj_text(scene.parts))
            col = p.createCollisionShape(pybullet.GEOM_MESH, fileName=path)
        finally:
            os.unlink(path)
        pos, quat = _pose_from_T(scene.T_object)
        body = p.createMultiBody(baseMass=float(scene.mass_kg), baseCollisionShapeIndex=col, basePosition=pos,
                                 baseOrientation=quat)
        # PyBullet multiplies the two bodies' coefficients: 1 here leaves the links' and the table's own
        p.changeDynamics(body, -1, lateralFriction=1.0, restitution=float(scene.config.restitution), **margin)
        return body

    def _table(self, scene) -> int:
        """A static box whose top face is the plane z = ``scene.table_z``, 2 m square under the object."""
        pybullet = sys.modules["pybullet"]  # imported quietly by __init__
        p = self._p
        c = np.asarray(scene.truth.bounds, float).mean(axis=0)
        col = p.createCollisionShape(pybullet.GEOM_BOX, halfExtents=[1.0, 1.0, 0.05])
        body = p.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=col,
                                 basePosition=[float(c[0]), float(c[1]), float(scene.table_z) - 0.05])
        # PyBullet combines rolling (spinning) friction as a's rolling times b's lateral friction plus
        # b's times a's: the object's lateral friction is 1 and its own rolling friction 0, so the
        # table's value is the pair's.
        p.changeDynamics(body, -1, lateralFriction=float(scene.config.table_friction), restitution=0.0,
                         rollingFriction=float(scene.config.rolling_friction_m),
                         spinningFriction=float(scene.config.spinning_friction_m))
        return body

    def _physics_step(self) -> None:
        """One physics step, with the support's rolling and spinning resistance where the world
        applies it (:attr:`_resistance`)."""
        if self._resistance is not None:
            self._resistance.apply()
        self._step_sim()

    def step_passive(self) -> None:
        """One physics step without commanding the arm (settling the scene)."""
        self._physics_step()
        self.steps += 1

    # --- evaluation only (oracle); never handed to the exploration ---------------------------------
    @property
    def client(self):
        """The underlying PyBullet client (evaluation and rendering only)."""
        return self._p

    def close(self) -> None:
        try:
            self._p.disconnect()
        except Exception:  # already disconnected
            pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class SimRobot(Robot):
    """The simulated arm behind the :class:`~explore3d.robot.interface.Robot` door: commands go to the
    world's motors, readings come back through :class:`~explore3d.robot.sensing.Sensors`.

    It keeps only closures over the world's actuator and sensor calls (no client, no object, no
    world query); ``reseed(key)`` seeds the sensor noise (per wrap)."""

    def __init__(self, world: ArmSimulation, sensors: SensorConfig = SensorConfig()):
        self.spec = world.spec
        self.dt = float(world.config.timestep)
        self.gravity = np.asarray(world.config.gravity, dtype=np.float64)
        self.sensors = sensors
        self._sense = Sensors(sensors)
        self._actuate_start = world._start
        self._actuate_step = world._step
        self._base = np.eye(4)
        self._k = 0

    def reseed(self, key) -> None:
        """Seed the sensor noise with ``(sensors.seed, *key)``."""
        self._sense.reseed(key)

    @property
    def base_pose(self) -> np.ndarray:
        return self._base.copy()

    def start(self, T_world_base, q0) -> JointReading:
        self._base = np.asarray(T_world_base, dtype=np.float64).copy()
        self._k = 0
        q, dq, tau = self._sense.restart(*self._actuate_start(T_world_base, q0))
        return JointReading(t_s=0.0, q=q, dq=dq, tau=tau)

    def step(self, command: JointCommand) -> JointReading:
        q, dq, tau = self._sense.measure(*self._actuate_step(command))
        self._k += 1
        return JointReading(t_s=self._k * self.dt, q=q, dq=dq, tau=tau)
