"""A parallel-jaw gripper's geometry: what the grasp planner checks for collisions and what the
grasp execution builds in the simulator, from one description.

Frames: a grasp pose ``T_mesh_grasp`` (4, 4) maps grasp-frame coordinates to the frame of the mesh
it was planned on.  In the grasp frame the origin is the grasp centre (midway between the two
contacts), +x the closing axis (from the first contact towards the second), +z the approach
direction (the gripper travels along +z onto the object; the palm lies towards -z) and
+y = z x x.  Lengths in metres, forces in newtons, masses in kilograms.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from explore3d.core.validate import check_field


@dataclass(frozen=True)
class GripperSpec:
    """A parallel-jaw gripper (SI units).

    Attributes:
        stroke_m: the widest opening between the finger pads, m.  0.14 m (as Robotiq's 2F-140):
            the built-in objects are at most 0.126 m across (the cylinder).
        finger_length_m: along the approach (z), from the palm to the finger tips.
        tip_m: how far the finger tips reach beyond the contacts along the approach, m; the palm
            then lies ``finger_length_m - tip_m`` behind the grasp centre, so an object may stand
            that deep between the fingers.
        finger_width_m: across the pads (y).
        finger_thickness_m: along the closing axis (x).
        palm_depth_m, palm_width_m: the palm's size along z and y (along x it spans the fingers
            fully open).
        clearance_m: the fingers open this much wider than the grasp's width on each side before
            the approach (at most to ``stroke_m``).
        approach_m: how far the gripper travels along its approach onto the grasp pose; the
            planner checks the whole swept path.
        grip_force_n: the force each finger presses with once closed, N.
        friction: Coulomb coefficient between pads and object (the planner's friction cone and
            the execution's pads): 0.8, rubber pads on wood or plastic (0.6-1.0).  At 0.5 (a
            26.6-degree cone) no pair on the cone's 32-degree sides is antipodal.
        spin_friction_m: torsional friction of a pad, m (PyBullet's ``spinningFriction``: about
            the friction coefficient times a pad's contact radius: 0.8 x 3 mm).
        finger_mass_kg, palm_mass_kg: the execution's bodies.
    """

    stroke_m: float = 0.14
    finger_length_m: float = 0.08
    tip_m: float = 0.015
    finger_width_m: float = 0.02
    finger_thickness_m: float = 0.01
    palm_depth_m: float = 0.02
    palm_width_m: float = 0.04
    clearance_m: float = 0.01
    approach_m: float = 0.08
    grip_force_n: float = 20.0
    friction: float = 0.8
    spin_friction_m: float = 0.0024
    finger_mass_kg: float = 0.05
    palm_mass_kg: float = 0.3

    def __post_init__(self):
        for name in ("stroke_m", "finger_length_m", "finger_width_m", "finger_thickness_m", "palm_depth_m",
                     "palm_width_m", "grip_force_n", "friction", "finger_mass_kg", "palm_mass_kg"):
            check_field(self, name, lo=0.0, strict=True)
        for name in ("clearance_m", "approach_m", "spin_friction_m"):
            check_field(self, name, lo=0.0)
        check_field(self, "tip_m", lo=0.0, hi=self.finger_length_m, unit="m (at most finger_length_m)")

    @property
    def friction_angle(self) -> float:
        """The friction cone's half angle, rad: atan(friction)."""
        return float(np.arctan(self.friction))

    def opening(self, width) -> np.ndarray:
        """The pre-grasp opening (m) for grasp widths ``width`` (m): width + 2 clearance, at most
        the stroke."""
        return np.minimum(np.asarray(width, dtype=float) + 2.0 * self.clearance_m, self.stroke_m)

    def boxes(self, opening: float, swept: bool = True) -> list[tuple[np.ndarray, np.ndarray]]:
        """The gripper as boxes in the grasp frame: [(centre (3,), half extents (3,))], metres: the
        two fingers open to ``opening`` (m between the pads) and the palm; with ``swept`` each box is
        stretched back along -z over ``approach_m``, the space it passes through on the approach."""
        t, back = self.finger_thickness_m, self.approach_m if swept else 0.0
        z_hi = -(self.finger_length_m - self.tip_m)  # the palm's face
        out = []
        for side in (-1.0, 1.0):  # fingers: z from the palm's face (less the approach) to the tips
            lo, hi = z_hi - back, self.tip_m
            out.append((np.array([side * (0.5 * opening + 0.5 * t), 0.0, 0.5 * (lo + hi)]),
                        np.array([0.5 * t, 0.5 * self.finger_width_m, 0.5 * (hi - lo)])))
        z_lo = z_hi - self.palm_depth_m - back
        out.append((np.array([0.0, 0.0, 0.5 * (z_lo + z_hi)]),
                    np.array([0.5 * self.stroke_m + t, 0.5 * self.palm_width_m, 0.5 * (z_hi - z_lo)])))
        return out


def box_corners(centre, half) -> np.ndarray:
    """(8, 3) the corners of the axis-aligned box ``centre`` (3,) +- ``half`` (3,)."""
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
    return np.asarray(centre, float) + signs * np.asarray(half, float)
