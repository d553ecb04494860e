"""One PyBullet world: the arm, optionally a static object, gravity.  A thin stateful wrapper.

:class:`ArmSimulation` owns its own PyBullet DIRECT client (no global client), so several can
live in one process and in parallel processes.  It holds no geometry logic.

What the exploration may use (see :mod:`explore3d.encircle`): :meth:`set_base` (a known base
transform), :meth:`reset_joints`, :meth:`step` (send joint references, advance, read joint
angles) and :attr:`spec`.  Nothing here reports contacts, distances or the object's pose to the
exploration; the evaluation-only oracle lives in :mod:`explore3d.quality`.

Quaternions passed to PyBullet are (x, y, z, w).
"""
from __future__ import annotations

import functools
import os
import tempfile
from dataclasses import dataclass

import numpy as np

from .arm import ArmSpec
from .urdf import arm_urdf
from .kinematics import link_transforms


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
        collision_margin: PyBullet collision margin of the object and of every link, m
            (``changeDynamics(collisionMargin=...)``); None keeps PyBullet's defaults, which
            leave touching faces about 1 mm apart on a triangle mesh.
    """

    timestep: float = 1.0 / 240.0
    solver: str = "dantzig"
    position_gain: float = 0.3
    velocity_gain: float = 1.0
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    friction: float = 0.0
    collision_margin: float | None = None

    def __post_init__(self):
        if self.solver not in ("dantzig", "si"):
            raise ValueError(f"solver must be 'dantzig' or 'si'; got {self.solver!r}")
        if not (0 < self.timestep <= 0.05):
            raise ValueError(f"timestep must be in (0, 0.05] s; got {self.timestep}")
        if self.collision_margin is not None and not (0.0 <= self.collision_margin <= 0.01):
            raise ValueError(f"collision_margin must be in [0, 0.01] m or None; got {self.collision_margin}")


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
            None for free space (used to calibrate the contact band).
        config: physics settings.
    """

    def __init__(self, spec: ArmSpec, vertices=None, faces=None, config: SimConfig = SimConfig()):
        import pybullet
        from pybullet_utils import bullet_client

        self.spec = spec
        self.config = config
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
            self.arm = p.loadURDF(path, useFixedBase=True)
        finally:
            os.unlink(path)
        self.joints = list(range(spec.n_links))
        self.torques = list(spec.joint_torques())
        # Switch off the default velocity motors so POSITION_CONTROL alone drives the joints.
        p.setJointMotorControlArray(self.arm, self.joints, pybullet.VELOCITY_CONTROL, forces=[0.0] * len(self.joints))
        self.object = None
        margin = {} if config.collision_margin is None else {"collisionMargin": float(config.collision_margin)}
        if vertices is not None:
            v = np.asarray(vertices, dtype=np.float64)
            f = np.asarray(faces, dtype=np.int64)
            col = p.createCollisionShape(
                pybullet.GEOM_MESH, vertices=v.tolist(), indices=f.ravel().tolist(),
                flags=pybullet.GEOM_FORCE_CONCAVE_TRIMESH,
            )
            self.object = p.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=col)
            p.changeDynamics(self.object, -1, lateralFriction=config.friction, restitution=0.0, **margin)
        for j in [-1] + self.joints:
            p.changeDynamics(self.arm, j, lateralFriction=config.friction, restitution=0.0, **margin)
        self._pc = pybullet.POSITION_CONTROL
        self._world_frame = pybullet.WORLD_FRAME
        # The per-step calls bound to this client once: BulletClient's attribute lookup costs
        # more than the calls themselves in a 24-link loop (measured: a third of the loop).
        cid = p._client
        self._step_sim = functools.partial(pybullet.stepSimulation, physicsClientId=cid)
        self._joint_states = functools.partial(pybullet.getJointStates, physicsClientId=cid)
        self._motor_array = functools.partial(pybullet.setJointMotorControlArray, physicsClientId=cid)
        self._external_force = functools.partial(pybullet.applyExternalForce, physicsClientId=cid)
        self._q = np.zeros(spec.n_links)
        self.steps = 0
        self._q_ref = np.zeros(spec.n_links)
        self._dq_ref = np.zeros(spec.n_links)
        self._forces = np.array(self.torques)
        self._T_base = np.eye(4)
        self._g_in_plane = True
        self._state = p.saveState()

    # --- what the exploration may call -------------------------------------------------------
    def set_base(self, T_world_base) -> None:
        """Put the arm's base at the known pose ``T_world_base`` (4, 4) and restore the initial
        physics state, so every wrap starts from the same state whatever ran before."""
        self._p.restoreState(self._state)
        self._T_base = np.asarray(T_world_base, dtype=np.float64).copy()
        # Gravity along the joint axes (the arm's plane horizontal) loads no joint: nothing to cancel.
        g = np.asarray(self.config.gravity, dtype=np.float64)
        self._g_in_plane = float(np.linalg.norm(g - (g @ self._T_base[:3, 2]) * self._T_base[:3, 2])) > 1e-9
        pos, quat = _pose_from_T(T_world_base)
        self._p.resetBasePositionAndOrientation(self.arm, pos, quat)
        self._q = self.joint_angles()

    def reset_joints(self, q) -> None:
        """Teleport the joints to angles ``q`` (n,), rad, at rest; references follow."""
        q = np.asarray(q, dtype=np.float64)
        for j, qj in zip(self.joints, q):
            self._p.resetJointState(self.arm, j, float(qj), 0.0)
        self._q = self.joint_angles()
        self._q_ref = q.copy()
        self._dq_ref = np.zeros_like(q)
        self._forces = np.array(self.torques)
        self._send()

    def _send(self) -> None:
        c = self.config
        n = len(self.joints)
        self._motor_array(
            self.arm, self.joints, self._pc, targetPositions=self._q_ref.tolist(),
            targetVelocities=self._dq_ref.tolist(), forces=self._forces.tolist(),
            positionGains=[c.position_gain] * n, velocityGains=[c.velocity_gain] * n,
        )

    def _compensate_gravity(self) -> None:
        # Joint torques that cancel the links' weights, tau = sum_i J_i^T (-m_i g), are exactly
        # the generalised force of an upward force m_i g at each link's centre of mass; PyBullet's
        # position motors take no feed-forward torque, so the motors' compensation is applied in
        # that equivalent form.  Computed from the robot's own model: measured joint angles, the
        # known base pose, link masses and the gravity vector.
        T = link_transforms(self.spec, self._q, self._T_base)  # the angles measured after the last step
        com = T[:, :3, 3] + T[:, :3, 0] * (self.spec.link_length / 2.0)
        f = (-self.spec.link_mass * np.asarray(self.config.gravity, dtype=np.float64)).tolist()
        for j, c in zip(self.joints, com.tolist()):
            self._external_force(self.arm, j, f, c, self._world_frame)

    def step(self, q_ref, dq_ref=None, forces=None, gravity_compensation: bool = False) -> np.ndarray:
        """Command references ``q_ref`` (n,), rad, optionally velocity references ``dq_ref`` (n,),
        rad/s (default 0), and motor torque limits ``forces`` (n,), N m (default: the arm's
        :meth:`~explore3d.arm.ArmSpec.joint_torques`, clipped to them); advance one timestep;
        return the measured joint angles (n,), rad.

        ``gravity_compensation``: the motors also cancel the links' weights (computed from the
        robot's own model, see :meth:`_compensate_gravity`), so the position loop sees no
        gravity load in any orientation of the arm's plane."""
        n = len(self.joints)
        dq = np.zeros(n) if dq_ref is None else dq_ref
        f = self.torques if forces is None else np.minimum(forces, self.torques)
        if not (np.array_equal(q_ref, self._q_ref) and np.array_equal(dq, self._dq_ref)
                and np.array_equal(f, self._forces)):
            self._q_ref = np.array(q_ref, dtype=np.float64)
            self._dq_ref = np.array(dq, dtype=np.float64)
            self._forces = np.array(f, dtype=np.float64)
            self._send()
        if gravity_compensation and self._g_in_plane:
            self._compensate_gravity()
        self._step_sim()
        self.steps += 1
        return self.joint_angles()

    def joint_angles(self) -> np.ndarray:
        """Measured joint angles (n,), rad."""
        self._q = np.fromiter((s[0] for s in self._joint_states(self.arm, self.joints)), float, len(self.joints))
        return self._q.copy()

    # --- evaluation only (oracle); never called by the exploration ---------------------------
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
