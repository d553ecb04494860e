"""The arm: a planar serial chain of identical box links with parallel revolute joints.

Frames (pytransform3d-style names: ``T_a_b`` maps b-coordinates to a-coordinates):

* ``base``: the arm's fixed base frame.  Joint 0 sits at its origin.  All joint axes are +z of
  the base frame, so the arm moves in the base x-y plane ("the arm's plane").
* ``link i`` (i = 0..n-1): origin at joint i, x along the link, z the joint axis.  With all joint
  angles zero the arm lies straight along base +x.  Link i spans x in [0, L], y in [-W/2, W/2],
  z in [-H/2, H/2] (L, W, H = ``link_length``, ``link_width``, ``link_height``).
* A *positive* joint angle curls the distal chain towards +y: the *inner face* of every link is
  its +y face (y = +W/2), the *outer face* its -y face.

The URDF written by :func:`explore3d.arm.urdf.arm_urdf` uses exactly this geometry for collision
boxes, so the surface points of :mod:`explore3d.arm.kinematics` lie on the simulated links' faces.
This module is the arm's model only (no URDF text, no simulator).
"""
from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from explore3d.core.validate import check_positive

#: Standard gravity, m/s^2 (used to size motor torques).
GRAVITY_M_S2 = 9.81

#: The base block's front face stands this far behind joint 0, metres (the block spans x in
#: [-BASE_GAP_M - base_size, -BASE_GAP_M] of the base frame, y and z in [-base_size/2, base_size/2]).
BASE_GAP_M = 1.0e-3

@dataclass(frozen=True)
class ArmSpec:
    """A chain of ``n_links`` identical box links (SI units).

    Attributes:
        name: identifier written into the URDF.
        n_links: number of links (= number of revolute joints), >= 1.
        link_length: joint-to-joint distance L, metres.
        link_width: in-plane thickness W (the curl direction), metres.
        link_height: out-of-plane thickness H (along the joint axes), metres.
        link_mass: mass of one link, kg.
        joint_lower: lower joint limit, rad (negative = bends outward).
        joint_upper: upper joint limit, rad (positive = curls inward).
        max_torque: motor torque limit of the most distal joint, N m.  Proximal joints get this
            plus what they need to hold the distal chain against gravity in any orientation
            (see :meth:`joint_torques`).
        base_size: edge of the cubic base block, metres (the base block sits behind joint 0,
            :data:`BASE_GAP_M` from it).
    """

    name: str = "default"
    n_links: int = 24
    link_length: float = 0.02
    link_width: float = 0.008
    link_height: float = 0.01
    link_mass: float = 0.01
    joint_lower: float = -0.5
    joint_upper: float = 2.0
    max_torque: float = 1.0
    base_size: float = 0.02

    def __post_init__(self):
        if not isinstance(self.n_links, int) or isinstance(self.n_links, bool) or self.n_links < 1:
            raise ValueError(f"n_links must be an integer >= 1; got {self.n_links!r}")
        for field in ("link_length", "link_width", "link_height", "link_mass", "max_torque", "base_size"):
            check_positive(getattr(self, field), field)
        if not (self.joint_lower < 0.0 < self.joint_upper):
            raise ValueError(
                f"joint limits must satisfy joint_lower < 0 < joint_upper (rad); got [{self.joint_lower}, {self.joint_upper}]"
            )
        if not re.fullmatch(r"[A-Za-z0-9_\-]+", self.name):
            raise ValueError(f"arm name must be letters, digits, '_' or '-'; got {self.name!r}")

    @property
    def reach(self) -> float:
        """Length of the straight arm from joint 0 to the tip, metres."""
        return self.n_links * self.link_length

    def gravity_torques(self) -> tuple[float, ...]:
        """Largest static gravity torque on each joint, N m: the straight distal chain held
        horizontally in a vertical plane (an upper bound over all configurations)."""
        out = []
        for i in range(self.n_links):
            n_distal = self.n_links - i
            lever = n_distal * self.link_length / 2.0  # centre of mass of the straight distal chain
            out.append(n_distal * self.link_mass * GRAVITY_M_S2 * lever)
        return tuple(out)

    def inertia_bounds(self) -> tuple[float, ...]:
        """Moment of inertia, kg m^2, of the straight distal chain about each joint axis (an upper
        bound over configurations: a curled chain is closer to the axis)."""
        L, m = self.link_length, self.link_mass
        own = m * (L * L + self.link_width ** 2) / 12.0
        out = []
        for i in range(self.n_links):
            centres = (np.arange(self.n_links - i) + 0.5) * L
            out.append(float(np.sum(m * centres ** 2 + own)))
        return tuple(out)

    def joint_torques(self) -> tuple[float, ...]:
        """Motor torque limit of each joint, N m: ``max_torque`` plus twice the gravity bound
        (so every joint can hold the arm in any orientation and still push)."""
        return tuple(self.max_torque + 2.0 * g for g in self.gravity_torques())

    def to_dict(self) -> dict:
        return asdict(self)


#: The paper's hardware: four modules of 110 mm (section IV), ~1 kg each (4 kg in all).
PAPER_ARM = ArmSpec(
    name="paper",
    n_links=4,
    link_length=0.11,
    link_width=0.04,
    link_height=0.04,
    link_mass=1.0,
    joint_lower=-0.5,
    joint_upper=2.0,
    max_torque=5.0,
    base_size=0.05,
)

#: Our default: many small links (the paper's conclusion).  Sized so that the straight arm
#: (0.48 m) can wrap the largest cross-section of the built-in objects (the 63 mm cylinder's
#: axial section has a perimeter of 0.41 m).
DEFAULT_ARM = ArmSpec(name="default")

BUILTIN_ARMS: dict[str, ArmSpec] = {"paper": PAPER_ARM, "default": DEFAULT_ARM}




def link_angle_for_perimeter(spec: ArmSpec, perimeter: float) -> float:
    """Mean joint angle, rad, of a chain wrapped once around a convex outline of ``perimeter`` metres."""
    return 2.0 * math.pi * spec.link_length / perimeter
