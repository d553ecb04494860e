"""Antipodal grasps for a parallel-jaw gripper, planned on a mesh alone (pure geometry).

A grasp is a pair of surface points the two finger pads close on.  Sampling (as Dex-Net's
antipodal sampler does): a seeded sample of surface points ``p1`` with their outward face normals
``n1``; from each, a ray into the body along ``-n1`` finds where it leaves, ``p2`` with normal
``n2``.  The closing axis ``x = (p2 - p1) / |p2 - p1|`` lies inside the first contact's friction
cone by construction; the pair is kept when it lies inside the second's too (angle between ``x``
and ``n2`` at most atan(friction)) and its width fits the stroke.  About the axis, approach
directions are tried from the most downward (a top grasp) round to the most upward; the first
whose gripper, swept along its approach, neither meets the mesh (python-fcl through trimesh) nor
goes below a stated table plane is the pair's grasp.  The N best pairs by quality, each at
least a stated distance from the others, are returned.

Quality (higher is better, in [0, 1]): ``(1 - angle / friction angle) * (1 - d / r)`` with
``angle`` the pair's antipodal angle (rad), ``d`` the distance (m) from the mesh's centre of mass
(uniform density) to the grasp axis (gravity's lever about the axis, which only the pads'
torsional friction resists) and ``r`` the largest distance of a vertex from the centre of mass.

Frames: every array is in the mesh's frame, metres; ``T_mesh_grasp`` as in
:mod:`explore3d.grasp.gripper`.
"""
from __future__ import annotations

from dataclasses import dataclass

import fcl
import numpy as np
import trimesh

from explore3d.core.validate import check_field
from explore3d.geometry.metrics import check_volume
from explore3d.grasp.gripper import GripperSpec, box_corners

#: How far inside the surface a ray starts, m: embree intersects in float32 (about 1e-7 relative,
#: 1e-8 m on a 0.1 m object); 0.1 mm keeps the ray off its own start face yet far below a wall.
RAY_START_INSET_M = 1e-4

#: Two grasps closer than ``SamplerConfig.min_separation_m`` are the same grasp when their axes are
#: within 15 degrees (a sphere's grasps all share its centre, on different diameters).
COS_SAME_AXIS = float(np.cos(np.radians(15.0)))

#: How far above the table plane every part of the gripper must stay, m.
TABLE_CLEARANCE_M = 0.001


@dataclass(frozen=True)
class GraspSet:
    """Grasps planned on one mesh, best first (mesh frame, metres).

    Attributes:
        poses: (n, 4, 4) ``T_mesh_grasp`` of each grasp (:mod:`explore3d.grasp.gripper`).
        contacts: (n, 2, 3) the two pad contacts, m.
        widths: (n,) the distance between the contacts, m.
        openings: (n,) the fingers' opening on the approach, m.
        quality: (n,) in [0, 1], higher is better (module docstring).
        angles: (n,) the antipodal angle, rad.
        com_distances: (n,) the centre of mass's distance from the grasp axis, m.
        n_antipodal: how many sampled pairs were antipodal and fitted the stroke (before the
            collision checks).
    """

    poses: np.ndarray
    contacts: np.ndarray
    widths: np.ndarray
    openings: np.ndarray
    quality: np.ndarray
    angles: np.ndarray
    com_distances: np.ndarray
    n_antipodal: int = 0

    def __len__(self) -> int:
        return int(len(self.widths))

    def select(self, index) -> "GraspSet":
        """The grasps at ``index`` (an index array or mask), in that order (copies)."""
        idx = np.atleast_1d(np.arange(len(self))[index])
        return GraspSet(self.poses[idx], self.contacts[idx], self.widths[idx], self.openings[idx], self.quality[idx],
                        self.angles[idx], self.com_distances[idx], self.n_antipodal)

    def to_dicts(self) -> list[dict]:
        """One JSON-ready dict per grasp: ``pose`` (4 x 4), ``contacts_m``, ``width_m``,
        ``opening_m``, ``quality``, ``angle_rad``, ``com_distance_m``."""
        return [{"pose": self.poses[i].tolist(), "contacts_m": self.contacts[i].tolist(),
                 "width_m": float(self.widths[i]), "opening_m": float(self.openings[i]),
                 "quality": float(self.quality[i]), "angle_rad": float(self.angles[i]),
                 "com_distance_m": float(self.com_distances[i])} for i in range(len(self))]


@dataclass(frozen=True)
class SamplerConfig:
    """How many candidates the sampler tries (seeded; SI units).

    Attributes:
        n_samples: surface points sampled, each two candidate pairs.
        n_approaches: approach directions tried about a pair's axis.
        min_separation_m: no two returned grasps with centres closer than this, m, and axes within
            15 degrees (so the N best are N different grasps, not one repeated).
    """

    n_samples: int = 1000
    n_approaches: int = 8
    min_separation_m: float = 0.005

    def __post_init__(self):
        check_field(self, "n_samples", lo=1, integer=True)
        check_field(self, "n_approaches", lo=1, integer=True)
        check_field(self, "min_separation_m", lo=0.0, unit="m")


def _empty(n_antipodal: int) -> GraspSet:
    z = np.zeros(0)
    return GraspSet(np.zeros((0, 4, 4)), np.zeros((0, 2, 3)), z, z, z, z, z, n_antipodal)


def _cone_directions(axis: np.ndarray, half_angle: float, rng: np.random.Generator) -> np.ndarray:
    """(k, 3) unit directions drawn uniformly in angle (up to ``half_angle``, rad) and azimuth about
    the unit ``axis`` (k, 3)."""
    helper = np.where(np.abs(axis[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u, axis=1)[:, None]
    v = np.cross(axis, u)
    tilt = rng.uniform(0.0, half_angle, len(axis))[:, None]
    phi = rng.uniform(0.0, 2.0 * np.pi, len(axis))[:, None]
    return np.cos(tilt) * axis + np.sin(tilt) * (np.cos(phi) * u + np.sin(phi) * v)


def antipodal_pairs(mesh: trimesh.Trimesh, gripper: GripperSpec, n_samples: int, rng: np.random.Generator):
    """Antipodal contact pairs of ``mesh`` that fit the stroke: (p1 (k, 3), p2 (k, 3), angle (k,)),
    m and rad.  Each sampled surface point casts two rays into the body: along its inward normal and
    along a direction drawn inside its friction cone (which finds the symmetric pairs of tapered
    faces, a cone's sides); ``angle`` is the larger of the two contacts' angles to the axis."""
    p, fi = trimesh.sample.sample_surface(mesh, n_samples, seed=rng)
    inward = -np.asarray(mesh.face_normals, float)[fi]
    p1 = np.vstack([p, p])
    d = np.vstack([inward, _cone_directions(inward, gripper.friction_angle, rng)])
    n1 = -np.vstack([inward, inward])
    loc, ray, tri = mesh.ray.intersects_location(p1 + RAY_START_INSET_M * d, d, multiple_hits=False)
    p2 = np.full_like(p1, np.nan)
    n2 = np.zeros_like(p1)
    p2[ray] = loc
    n2[ray] = np.asarray(mesh.face_normals, float)[tri]
    hit = np.isfinite(p2[:, 0])
    axis = np.where(hit[:, None], p2 - p1, d)
    width = np.linalg.norm(axis, axis=1)
    axis = axis / np.where(width > 0.0, width, 1.0)[:, None]
    angle1 = np.arccos(np.clip(-np.einsum("ij,ij->i", n1, axis), -1.0, 1.0))
    angle2 = np.arccos(np.clip(np.einsum("ij,ij->i", n2, axis), -1.0, 1.0))
    angle = np.maximum(angle1, angle2)
    ok = hit & (angle <= gripper.friction_angle) & (width > 0.0) & (width <= gripper.stroke_m - gripper.clearance_m)
    return p1[ok], p2[ok], angle[ok]


def _frame(axis: np.ndarray, approach: np.ndarray, centre: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 0] = axis
    T[:3, 1] = np.cross(approach, axis)
    T[:3, 2] = approach
    T[:3, 3] = centre
    return T


def _approaches(axis: np.ndarray, k: int, phase: float) -> np.ndarray:
    """(k, 3) unit directions perpendicular to ``axis``, evenly spaced from ``phase``, the most
    downward (most negative z) first."""
    helper = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    phi = phase + 2.0 * np.pi * np.arange(k) / k
    z = np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v
    return z[np.argsort(z[:, 2], kind="stable")]


class MeshCollider:
    """Boxes against one closed mesh (mesh frame, metres): python-fcl's box-triangle test, and for a
    box that meets no triangle, whether its centre lies inside (a box wholly inside the mesh meets
    no triangle either)."""

    def __init__(self, mesh: trimesh.Trimesh):
        self.mesh = mesh
        self._object = fcl.CollisionObject(trimesh.collision.mesh_to_BVH(mesh), fcl.Transform())

    def box_hits(self, R: np.ndarray, centre: np.ndarray, half: np.ndarray) -> bool:
        """Whether the box of half extents ``half`` (3,), rotated by ``R`` (3, 3) and centred at
        ``centre`` (3,), overlaps the mesh."""
        box = fcl.CollisionObject(fcl.Box(*(2.0 * half)), fcl.Transform(R, centre))
        if fcl.collide(box, self._object, fcl.CollisionRequest(), fcl.CollisionResult()):
            return True
        return bool(self.mesh.contains(centre[None, :])[0])


def gripper_clear(collider: MeshCollider, gripper: GripperSpec, T: np.ndarray, opening: float,
                  table_z: float | None) -> bool:
    """Whether the gripper at grasp pose ``T`` (4, 4), open to ``opening`` m and swept along its
    approach, stays off the mesh and above ``table_z`` (m, or None)."""
    boxes = gripper.boxes(opening)
    if table_z is not None:
        lowest = min((box_corners(c, h) @ T[:3, :3].T)[:, 2].min() for c, h in boxes) + T[2, 3]
        if lowest < table_z + TABLE_CLEARANCE_M:
            return False
    return not any(collider.box_hits(T[:3, :3], T[:3, :3] @ c + T[:3, 3], h) for c, h in boxes[::-1])  # palm first


def sample_grasps(mesh: trimesh.Trimesh, n: int = 20, gripper: GripperSpec = GripperSpec(), seed: int = 0,
                  table_z: float | None = None, config: SamplerConfig = SamplerConfig()) -> GraspSet:
    """The ``n`` best collision-free antipodal grasps on ``mesh`` (module docstring).

    Args:
        mesh: closed trimesh, metres (an estimate or a true mesh).
        n: how many grasps to return at most (fewer when fewer pass).
        gripper: the gripper's geometry, stroke and friction.
        seed: seed of the surface samples and approach phases (same seed, same grasps).
        table_z: the height of a table plane in the mesh's frame (z up), m; no part of the gripper
            may go below it.  None: no table.
        config: how many candidates to try.

    Returns:
        a :class:`GraspSet`, best first; empty when no pair is antipodal within the stroke (an
        object larger than the stroke) or none is reachable.
    """
    if not isinstance(mesh, trimesh.Trimesh):
        raise TypeError(f"mesh must be a trimesh.Trimesh (e.g. the run's estimate); got {type(mesh).__name__}")
    check_volume(mesh, "mesh")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n (how many grasps) must be an integer >= 1; got {n!r}")
    if not isinstance(gripper, GripperSpec):
        raise TypeError(f"gripper must be an explore3d GripperSpec; got {type(gripper).__name__}")
    if table_z is not None and not np.isfinite(float(table_z)):
        raise ValueError(f"table_z must be a finite height in metres or None; got {table_z!r}")
    rng = np.random.default_rng(seed)
    p1, p2, angle = antipodal_pairs(mesh, gripper, config.n_samples, rng)
    if not len(p1):
        return _empty(0)
    axis = (p2 - p1) / np.linalg.norm(p2 - p1, axis=1)[:, None]
    centre = 0.5 * (p1 + p2)
    com = np.asarray(mesh.center_mass, float)
    rel = com - centre
    d_com = np.linalg.norm(rel - np.einsum("ij,ij->i", rel, axis)[:, None] * axis, axis=1)
    r_max = float(np.linalg.norm(np.asarray(mesh.vertices, float) - com, axis=1).max())
    quality = (1.0 - angle / gripper.friction_angle) * np.clip(1.0 - d_com / r_max, 0.0, 1.0)
    phases = rng.uniform(0.0, 2.0 * np.pi, len(p1))
    order = np.argsort(-quality, kind="stable")

    collider = MeshCollider(mesh)
    width = np.linalg.norm(p2 - p1, axis=1)
    opening = gripper.opening(width)
    chosen, poses = [], []
    for i in order:
        if len(chosen) == n:
            break
        if chosen:
            near = np.linalg.norm(centre[chosen] - centre[i], axis=1) < config.min_separation_m
            if np.any(near & (np.abs(axis[chosen] @ axis[i]) > COS_SAME_AXIS)):
                continue
        for z in _approaches(axis[i], config.n_approaches, phases[i]):
            T = _frame(axis[i], z, centre[i])
            if gripper_clear(collider, gripper, T, float(opening[i]), table_z):
                chosen.append(i)
                poses.append(T)
                break
    if not chosen:
        return _empty(len(p1))
    idx = np.array(chosen)
    return GraspSet(poses=np.array(poses), contacts=np.stack([p1[idx], p2[idx]], axis=1), widths=width[idx],
                    openings=opening[idx], quality=quality[idx], angles=angle[idx], com_distances=d_com[idx],
                    n_antipodal=int(len(p1)))
