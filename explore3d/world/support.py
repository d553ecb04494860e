"""The support's rolling and spinning friction, applied by the world itself on the Dantzig solver.

Bullet's sequential-impulse solver adds rolling and spinning friction as constraint rows; its MLCP
(Dantzig) solver builds its problem from the contact and friction rows only and drops them
(measured: a ball set rolling at 0.2 m/s covers the same 0.36 m with ``rollingFriction`` 1e-3 m
as with 0).  A world on that solver therefore applies them as an external torque before each step
(:class:`SupportFriction`), computed by :func:`support_resistance` from the last step's support
contacts and the object's angular velocity.

This module is part of the simulated *world's physics*, like Bullet's own C++ solver: it reads the
object's state to push on the object and returns nothing to anyone, so no reading of the arm and
nothing the exploration sees comes from it.  It is one of the few modules allowed to name the
world queries (tests/test_robot.py); it binds them when first imported, which the world does when
it builds a table scene on the Dantzig solver.
"""
from __future__ import annotations

import math

import numpy as np
import pybullet

# Bound once, at import: the world's physics keeps them even where a test removes the world queries
# from the pybullet module to prove that the exploration runs without them.
_contact_points = pybullet.getContactPoints
_base_pose = pybullet.getBasePositionAndOrientation
_base_velocity = pybullet.getBaseVelocity
_external_torque = pybullet.applyExternalTorque


def support_resistance(omega, normal_n, rolling_m, spinning_m, up, inertia_roll, inertia_spin, dt) -> np.ndarray:
    """The torque (3,), N m, world frame, that rolling and spinning friction put on a body resting
    on a support: Coulomb-limited, against its angular velocity, never reversing it in one step.

    The world applies it on the Dantzig solver, which drops these rows (the module's docstring).

    Args:
        omega: (3,) the body's angular velocity, rad/s, world frame.
        normal_n: total normal force of the support's contacts, N (>= 0).
        rolling_m, spinning_m: the rolling and spinning friction lever arms, m
            (:attr:`~explore3d.core.settings.SceneConfig.rolling_friction_m` and ``spinning_friction_m``).
        up: (3,) unit normal of the support (the table's +z).
        inertia_roll, inertia_spin: moments of inertia, kg m^2, that bound the torque so one step
            of length ``dt`` (s) at most stops the rolling (about an axis in the support plane) and
            the spinning (about ``up``) component: the resistance holds a body still but never
            drives it.
    """
    omega = np.asarray(omega, dtype=np.float64)
    up = np.asarray(up, dtype=np.float64)
    spin = float(omega @ up)
    roll = omega - spin * up
    tau = np.zeros(3)
    if normal_n <= 0.0:
        return tau
    r = float(np.linalg.norm(roll))
    if r > 0.0 and rolling_m > 0.0:
        tau -= min(rolling_m * normal_n, inertia_roll * r / dt) * roll / r
    if spin != 0.0 and spinning_m > 0.0:
        tau -= math.copysign(min(spinning_m * normal_n, inertia_spin * abs(spin) / dt), spin) * up
    return tau


class SupportFriction:
    """The stated rolling and spinning friction between a resting object and the table of one
    PyBullet client, applied before each step (:meth:`apply`).

    Args:
        client: the PyBullet client id.
        body, table: the object's and the table's body ids.
        rolling_m, spinning_m: the rolling and spinning friction lever arms, m.
        mass_kg: the object's mass, kg.
        inertia_min: the object's least principal moment of inertia, kg m^2.
        table_z: the table's top, m, world frame.
        dt: the physics step, s.
    """

    def __init__(self, client: int, body: int, table: int, rolling_m: float, spinning_m: float, mass_kg: float,
                 inertia_min: float, table_z: float, dt: float):
        self.client, self.body, self.table = int(client), int(body), int(table)
        self.rolling_m, self.spinning_m = float(rolling_m), float(spinning_m)
        self.mass_kg, self.inertia_min = float(mass_kg), float(inertia_min)
        self.table_z, self.dt = float(table_z), float(dt)

    def apply(self) -> None:
        """Apply the resistance for the coming step (a no-op while the object is off the table)."""
        cid = self.client
        normal = sum(c[9] for c in _contact_points(self.body, self.table, physicsClientId=cid))  # the last step's
        if normal <= 0.0:
            return
        pos, _ = _base_pose(self.body, physicsClientId=cid)
        _, omega = _base_velocity(self.body, physicsClientId=cid)
        # about a horizontal axis through a support point the moment of inertia is at least the
        # least principal moment plus mass times the centre's height squared
        height = max(pos[2] - self.table_z, 0.0)
        tau = support_resistance(omega, normal, self.rolling_m, self.spinning_m, (0.0, 0.0, 1.0),
                                 self.inertia_min + self.mass_kg * height * height, self.inertia_min, self.dt)
        if tau.any():
            _external_torque(self.body, -1, tau.tolist(), pybullet.WORLD_FRAME, physicsClientId=cid)
