"""Where the arm may go when the object rests on a table: pure geometry on the arm's own model.

A robot is told the table's height.  Its plan keeps every link above the plane
``z = floor_z`` (the table top plus a clearance): a wrap's base pose is used only when the straight
arm and the base block clear it (:func:`pose_clears`), and each joint's sweep stops before the
carried chain would dip below it (:func:`floor_stop`), as at a joint limit.  Everything here is
forward kinematics of the model at commanded angles and the known base pose, nothing the
simulator is asked.

Frames follow :mod:`explore3d.arm.spec`: ``T_world_base`` (4, 4) maps base to world coordinates; link i
is the box ``[0, L] x [-W/2, W/2] x [-H/2, H/2]`` of its frame; the base block is the cube of edge
``base_size`` centred at ``(-base_size / 2 - BASE_GAP_M, 0, 0)``.  Metres, radians.
"""
from __future__ import annotations

import numpy as np

from explore3d.arm.kinematics import link_frames_planar
from explore3d.arm.spec import BASE_GAP_M, ArmSpec

__all__ = ["link_corners", "lowest_z", "base_lowest_z", "floor_stop", "pose_clears", "plan_lowest_z"]


def link_corners(spec: ArmSpec, q, T_world_base) -> np.ndarray:
    """(..., n, 8, 3) the corners of every link box at joint angles ``q`` (..., n), world frame."""
    origins, headings = link_frames_planar(spec, q)
    c, s = np.cos(headings)[..., None], np.sin(headings)[..., None]
    L, W, H = spec.link_length, spec.link_width, spec.link_height
    xs = np.array([0.0, L, L, 0.0, 0.0, L, L, 0.0])
    ys = np.array([-W, -W, W, W, -W, -W, W, W]) / 2.0
    zs = np.array([-H, -H, -H, -H, H, H, H, H]) / 2.0
    px = origins[..., 0:1] + c * xs - s * ys
    py = origins[..., 1:2] + s * xs + c * ys
    P = np.stack([px, py, np.broadcast_to(zs, px.shape), np.ones(px.shape)], axis=-1)
    return (P @ np.asarray(T_world_base, dtype=np.float64).T)[..., :3]


def lowest_z(spec: ArmSpec, q, T_world_base, first: int = 0) -> np.ndarray:
    """(...) the lowest world z, m, of links ``first``.. at joint angles ``q`` (..., n)."""
    return link_corners(spec, q, T_world_base)[..., first:, :, 2].min(axis=(-1, -2))


def base_lowest_z(spec: ArmSpec, T_world_base) -> float:
    """The lowest world z, m, of the base block."""
    b = spec.base_size
    g = np.array(np.meshgrid([-b - BASE_GAP_M, -BASE_GAP_M], [-b / 2, b / 2], [-b / 2, b / 2], indexing="ij"))
    P = np.c_[g.reshape(3, -1).T, np.ones(8)] @ np.asarray(T_world_base, dtype=np.float64).T
    return float(P[:, 2].min())


def pose_clears(spec: ArmSpec, T_world_base, floor_z: float) -> bool:
    """Whether the straight arm and the base block at ``T_world_base`` lie above ``floor_z`` (m)."""
    q0 = np.zeros(spec.n_links)
    return bool(lowest_z(spec, q0, T_world_base) >= floor_z and base_lowest_z(spec, T_world_base) >= floor_z)


def floor_stop(spec: ArmSpec, q_ref, k: int, T_world_base, floor_z: float, stop: float, step: float = 0.005) -> float:
    """The largest angle, rad, up to which joint ``k`` may sweep from ``q_ref[k]`` towards ``stop``
    (rad, above it) with the other joints at ``q_ref`` (n,) while every link it carries stays at or
    above ``floor_z`` (m); checked every ``step`` rad and at ``stop``.  ``q_ref[k]`` itself when
    the first step would already dip below (``stop`` when nothing does)."""
    q_ref = np.asarray(q_ref, dtype=np.float64)
    a0 = float(q_ref[k])
    if stop <= a0:
        return float(stop)
    angles = np.r_[np.arange(a0, stop, step), stop]
    Q = np.repeat(q_ref[None, :], len(angles), axis=0)
    Q[:, k] = angles
    below = np.nonzero(lowest_z(spec, Q, T_world_base, first=k) < floor_z)[0]
    if not len(below):
        return float(stop)
    i = int(below[0])
    return float(angles[i - 1]) if i > 0 else a0


def plan_lowest_z(spec: ArmSpec, q_refs, T_world_base) -> float:
    """The lowest world z, m, of any link at any of the commanded angles ``q_refs`` (t, n) and of
    the base block: what a plan (the references a controller sent) reaches down to."""
    q_refs = np.atleast_2d(np.asarray(q_refs, dtype=np.float64))
    return min(float(lowest_z(spec, q_refs, T_world_base).min()), base_lowest_z(spec, T_world_base))
