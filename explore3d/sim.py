"""One PyBullet world: the arm, optionally a static object, gravity.  A thin stateful wrapper.

:class:`ArmSimulation` (the world) owns its own PyBullet DIRECT client (no global client), so
several can live in one process and in parallel processes.  It holds no geometry logic.

The exploration never sees the world: it gets a :class:`SimRobot` (:meth:`ArmSimulation.robot`),
the :class:`~explore3d.robot.Robot` interface of the simulated arm, which reads the joints through
:mod:`explore3d.sensing` and holds no client.  The world's client (:attr:`ArmSimulation.client`)
is for the evaluation layer and rendering only.

Quaternions passed to PyBullet are (x, y, z, w).
"""
from __future__ import annotations

import functools
import os
import tempfile
from dataclasses import dataclass

import numpy as np

from ._validate import check_field
from .arm import ArmSpec
from .robot import JointCommand, JointReading, Robot
from .sensing import SensorConfig, Sensors
from .urdf import arm_urdf


@dataclass(frozen=True)
class SimConfig:
    """Physics settings (SI).

    Attributes:
        timestep: physics step, s.
        solver: "dantzig" (PyBullet's direct MLCP solver: stiff, held joints stay put) or
            "si" (the default sequential-impulse solver, soft for long chains).
        position_gain, velocity_gain: PyBullet POSITION_CONTROL motor gains (dimensionless,
            they scale the motor constraint's error reduction).
        gravity: gravity vector in the world frame, m/s^2.
        friction: Coulomb friction coefficient between the links and the object.  0 by default:
            measured on the 80 mm cube, PyBullet's friction made held links stick-slip against the
            surface (contact forces jumping between 0 and ~15 N from step to step), which read as
            false contacts; with frictionless contact the wrap is clean.
        collision_margin: PyBullet collision margin of the object and of the base block, m
            (``changeDynamics(collisionMargin=...)``; PyBullet leaves the links of a multibody at its
            1 mm whatever is asked, measured with getDynamicsInfo); None keeps PyBullet's defaults, which
            leave touching faces about 1 mm outside a triangle mesh.  Default 0.3 mm: measured on
            every built-in object (BENCHMARKS.md, "Thin contact margin"), touching faces then
            sit about 0.2 mm out; 0.1 mm and thinner let links sink up to 2-3 mm into the
            sphere's mesh, and 0 let the chain blow up.
        self_collision: the arm collides with itself (PyBullet's ``URDF_USE_SELF_COLLISION``):
            a link with every other link and with the base block, except the bodies a joint
            connects (link i with link i + 1, link 0 with the base), whose boxes meet at the joint
            and overlap on the inner side of a bent joint at every angle (by the model: 5.7 mm at
            the upper limit, 1.9 mm at the lower; link 0 and the base block 7.3 and 0.9 mm; with
            ``URDF_USE_SELF_COLLISION_INCLUDE_PARENT`` PyBullet reports every neighbouring pair
            touching even with the arm straight).  PyBullet excludes
            those parent-child pairs by default (``URDF_USE_SELF_COLLISION_EXCLUDE_PARENT`` adds
            nothing: measured, the same pairs collide with and without it; only
            ``URDF_USE_SELF_COLLISION_INCLUDE_PARENT`` would collide them).  A link's grandparent
            is not excluded: with two neighbouring joints near the upper limit link i + 2 folds
            into link i (default arm: they touch from 1.9 rad on both joints; at 2 rad PyBullet and
            the model overlap them by 3.6 mm), which a real arm of these boxes would feel.  The exploration tells such a touch from the object's by
            the arm's own kinematics (:mod:`explore3d.selfcontact`).  Measured with the Dantzig
            solver: a link lying on the base block now and then flips off it within one step
            (small16's tip: 0.417 rad in one step, the model's distance 0 -> 11 mm; 9 such flips in
            253 base-link contact steps of 6 default-arm wraps of the cube, against 31 in 10943
            arm-object contact steps).  Re-running that step with ERP 0.05 or 0.01, 200 solver
            iterations, split impulse or a 1 mm contact breaking threshold gives the same flip;
            the SI solver none (0.013 rad), PGS 0.023 rad, 4 substeps 0.35 rad; the base block as a
            separate static body instead of the arm's base link flips too (18 in 485).  The band
            calibration and the controller therefore judge a detection by the sweep's last
            readings, not its own (:data:`explore3d.encircle.SELF_CONTACT_WINDOW_STEPS`).  False: links pass through
            each other (the behaviour before self-collision existed).
        mass_error: the simulated arm's link masses and inertias differ from its model (the
            controller's) by a factor ``1 + e`` per link, ``e`` drawn uniformly from
            ``[-mass_error, mass_error]`` with ``mass_seed`` (:func:`mass_scales`;
            0: the model is exact).  The contact band is measured on this arm (as a robot measures
            its own free motion), the gravity feed-forward and the localisation use the model.
        mass_seed: seed of the mass error.
    """

    timestep: float = 1.0 / 240.0
    solver: str = "dantzig"
    position_gain: float = 0.3
    velocity_gain: float = 1.0
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    friction: float = 0.0
    collision_margin: float | None = 3.0e-4
    self_collision: bool = True
    mass_error: float = 0.0
    mass_seed: int = 0

    def __post_init__(self):
        if self.solver not in ("dantzig", "si"):
            raise ValueError(f"SimConfig.solver must be 'dantzig' or 'si'; got {self.solver!r}")
        check_field(self, "timestep", 0, "s", strict=True, hi=0.05)
        check_field(self, "position_gain", 0, strict=True)
        check_field(self, "velocity_gain", 0)
        check_field(self, "friction", 0)
        check_field(self, "mass_error", 0, hi=0.5)
        check_field(self, "mass_seed", 0, integer=True)
        if not isinstance(self.self_collision, bool):
            raise ValueError(f"SimConfig.self_collision must be True or False; got {self.self_collision!r}")
        if self.collision_margin is not None:
            check_field(self, "collision_margin", 0, "m (or None)", hi=0.01)
        g = np.asarray(self.gravity, dtype=float) if np.ndim(self.gravity) == 1 else None
        if g is None or g.shape != (3,) or not np.isfinite(g).all():
            raise ValueError(f"SimConfig.gravity must be 3 finite numbers, m/s^2, world frame; got {self.gravity!r}")


def mass_scales(n: int, mass_error: float, seed: int) -> np.ndarray:
    """(n,) factors of the simulated links' masses over the model's: ``1 + e``, ``e`` uniform in
    ``[-mass_error, mass_error]``, seeded (ones when ``mass_error`` is 0)."""
    if mass_error == 0:
        return np.ones(n)
    rng = np.random.default_rng([int(seed), 7919])
    return 1.0 + rng.uniform(-mass_error, mass_error, n)


def _pose_from_T(T) -> tuple[list, list]:
    """(position (3,), quaternion (x, y, z, w)) of a (4, 4) homogeneous transform."""
    from scipy.spatial.transform import Rotation

    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise ValueError(f"a base transform must be a finite (4, 4) matrix; got shape {T.shape}")
    return T[:3, 3].tolist(), Rotation.from_matrix(T[:3, :3]).as_quat().tolist()


class ArmSimulation:
    """The arm (fixed base) and an optional static triangle-mesh object in one DIRECT client.

    Args:
        spec: the arm.
        vertices, faces: the object as a (v, 3) float array (metres, world frame) and (f, 3) int
            array, loaded as a static concave mesh (``GEOM_FORCE_CONCAVE_TRIMESH``, mass 0); or
            None for free space.
        config: physics settings.
    """

    def __init__(self, spec: ArmSpec, vertices=None, faces=None, config: SimConfig = SimConfig(), scene=None):
        from ._quiet import quiet_c_output

        self.spec = spec
        self.config = config
        with quiet_c_output():  # PyBullet's C-level banners: build time, argv[0]=, solver switch
            import pybullet
            from pybullet_utils import bullet_client

            from ._interrupt import deferred_signals

            with deferred_signals():  # a Ctrl-C inside would leave a half-made client whose __del__ complains
                self._p = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
            p = self._p
            p.setGravity(*config.gravity)
            p.setTimeStep(config.timestep)
            if config.solver == "dantzig":
                p.setPhysicsEngineParameter(constraintSolverType=pybullet.CONSTRAINT_SOLVER_LCP_DANTZIG)
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
        if scene is not None and scene.parts:  # the arm waits far from the scene until a motion starts
            p.resetBasePositionAndOrientation(self.arm, [50.0, 50.0, 50.0], [0.0, 0.0, 0.0, 1.0])
        self._pc = pybullet.POSITION_CONTROL
        self._world_frame = pybullet.WORLD_FRAME
        # The per-step calls bound to this client once: BulletClient's attribute lookup costs
        # more than the calls themselves in a 24-link loop (measured: a third of the loop).
        cid = p._client
        self._step_sim = functools.partial(pybullet.stepSimulation, physicsClientId=cid)
        self._joint_states = functools.partial(pybullet.getJointStates, physicsClientId=cid)
        self._motor_array = functools.partial(pybullet.setJointMotorControlArray, physicsClientId=cid)
        self._external_torque = functools.partial(pybullet.applyExternalTorque, physicsClientId=cid)
        self.steps = 0
        #: evaluation only: called with the world after every commanded step (never by the exploration)
        self.step_observer = None
        self._torques = np.array(spec.joint_torques())
        self._sent = None
        self._axis = np.array([0.0, 0.0, 1.0])
        self._state = p.saveState()

    def robot(self, sensors: SensorConfig = SensorConfig()) -> "SimRobot":
        """The :class:`~explore3d.robot.Robot` interface of the simulated arm, read through ``sensors``."""
        return SimRobot(self, sensors)

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
        self._step_sim()
        self.steps += 1
        if self.step_observer is not None:  # the evaluation's (explore3d.scene.SceneWatch)
            self.step_observer(self)
        q, dq, _, tau = zip(*self._joint_states(self.arm, self.joints))
        return np.array(q, dtype=np.float64), np.array(dq, dtype=np.float64), np.array(tau, dtype=np.float64) + tau_ff

    # --- the scene's bodies (built once) ------------------------------------------------------------
    def _resting_object(self, scene, margin) -> int:
        """A free body of the scene's convex parts at its settled pose, mass ``scene.mass_kg``."""
        import pybullet

        from .scene import parts_obj_text

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
        import pybullet

        p = self._p
        c = np.asarray(scene.truth.bounds, float).mean(axis=0)
        col = p.createCollisionShape(pybullet.GEOM_BOX, halfExtents=[1.0, 1.0, 0.05])
        body = p.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=col,
                                 basePosition=[float(c[0]), float(c[1]), float(scene.table_z) - 0.05])
        p.changeDynamics(body, -1, lateralFriction=float(scene.config.table_friction), restitution=0.0)
        return body

    def step_passive(self) -> None:
        """One physics step without commanding the arm (settling the scene)."""
        self._step_sim()
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
    """The simulated arm behind the :class:`~explore3d.robot.Robot` door: commands go to the
    world's motors, readings come back through :class:`~explore3d.sensing.Sensors`.

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
