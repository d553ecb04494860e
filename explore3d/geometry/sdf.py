"""Signed distance to a true mesh and sampled link-box distances (evaluation only).

EVALUATION ONLY: these take the true object mesh; the exploration never does.

Geometry.  Link i is the box ``[0, L] x [-W/2, W/2] x [-H/2, H/2]`` in its own frame
(:mod:`explore3d.arm.spec`); ``T_world_link`` (4, 4) maps link coordinates to world coordinates
(:func:`explore3d.arm.kinematics.link_transforms`).  The distance of a link to the object is the
minimum of the object's *signed distance* (metres, positive outside, negative inside) over the
link's box surface, sampled on a grid of a given pitch.  The signed distance is 1-Lipschitz, so
a sampled minimum overestimates the true one by at most the grid's covering radius (the largest
distance of a surface point from its nearest sample); :func:`box_min_distance` uses that bound to
prune links far from the surface coarse-to-fine, so only links near the surface are sampled
finely.  Penetration depth is the largest negative signed distance over the same samples: the
deepest point of a box pressed into a flat face lies on the box surface, so for the shallow
penetrations met here this is the box's penetration; in general it is a lower bound.

Why links touching the object sit ~1 mm off its surface with PyBullet's default margin: PyBullet
gives the static concave triangle mesh a 1 mm collision margin (measured: ``getClosestPoints``
between a link face and the mesh returns the geometric gap minus 1.000 mm,
:data:`PYBULLET_MESH_MARGIN_M`), so the contact constraint holds a face about that far out
(``SimConfig.collision_margin`` sets it thinner).
"""
from __future__ import annotations

import math

import numpy as np
import trimesh

from explore3d.arm.spec import ArmSpec
from explore3d.core.interrupt import import_optional

__all__ = ["BOX_FACES", "DETECTION_CONFIG_PITCH_M", "PYBULLET_MESH_MARGIN_M", "SignedDistance", "TRAJECTORY_PITCH_M",
           "box_min_distance", "box_surface_points", "face_min_distance"]

#: PyBullet's collision margin of a static concave triangle mesh (GEOM_MESH with
#: GEOM_FORCE_CONCAVE_TRIMESH), metres.  Measured with pybullet 3.2.7: a straight link whose
#: inner face is g metres from a face of the cube gets ``getClosestPoints`` distance g - 1.000 mm
#: for g from -1 to +10 mm (tests/test_quality.py checks it).  A resting contact therefore sits
#: about this far outside the geometric surface.
PYBULLET_MESH_MARGIN_M = 1.0e-3

#: Sampling pitch of the box surface for final and detection configurations, metres (measured
#: sampling error near the surface <= 0.09 mm against a 0.1 mm reference grid on the cube).
DETECTION_CONFIG_PITCH_M = 1.0e-3

#: Sampling pitch along trajectories, metres (measured error near the surface <= 0.2 mm).
TRAJECTORY_PITCH_M = 2.5e-3

#: Names of the box faces, in the order of the face codes of :func:`box_surface_points`.
BOX_FACES = ("inner", "outer", "top", "bottom", "proximal", "distal")

# --- signed distance to the true mesh ------------------------------------------------------------
class SignedDistance:
    """Signed distance to a closed triangle mesh, metres, positive outside and negative inside.

    Args:
        mesh: a closed, outward-wound ``trimesh.Trimesh`` (metres, world frame).
        backend: "open3d" (``RaycastingScene.compute_signed_distance``, float32 about the mesh's
            bounding-box centre: ~1e-8 m rounding for 0.1 m objects; fast), "trimesh"
            (``trimesh.proximity.signed_distance``, float64, ~100x slower) or "auto" (open3d if it
            imports, else trimesh).

    Calling it with points (..., 3), metres, world frame, returns (...) distances.
    """

    def __init__(self, mesh, backend: str = "auto"):
        if backend not in ("auto", "open3d", "trimesh"):
            raise ValueError(f"backend must be 'auto', 'open3d' or 'trimesh'; got {backend!r}")
        V = np.asarray(getattr(mesh, "vertices", None), dtype=np.float64)
        F = np.asarray(getattr(mesh, "faces", None), dtype=np.int64)
        if V.ndim != 2 or V.shape[1:] != (3,) or F.ndim != 2 or F.shape[1:] != (3,) or len(F) == 0:
            raise ValueError("mesh must be a trimesh.Trimesh with (v, 3) vertices and (f, 3) faces")
        self.mesh = mesh
        self.centre = (V.min(0) + V.max(0)) / 2.0
        self._scene = None
        if backend in ("auto", "open3d"):
            try:
                o3d = import_optional("open3d")  # optional, heavy; an interrupted import raises KeyboardInterrupt
            except (ImportError, OSError) as exc:
                if backend == "open3d":
                    raise ImportError(f"open3d could not be imported ({exc}); pip install open3d-cpu, "
                                      "or use backend='trimesh'") from None
            else:
                self._o3d = o3d
                self._scene = o3d.t.geometry.RaycastingScene()
                self._scene.add_triangles(o3d.core.Tensor((V - self.centre).astype(np.float32)),
                                          o3d.core.Tensor(F.astype(np.uint32)))
        self.backend = "open3d" if self._scene is not None else "trimesh"

    def __call__(self, points) -> np.ndarray:
        P = np.asarray(points, dtype=np.float64)
        if P.shape[-1:] != (3,):
            raise ValueError(f"points must have shape (..., 3); got {P.shape}")
        flat = P.reshape(-1, 3)
        if flat.shape[0] == 0:
            return np.zeros(P.shape[:-1])
        if self._scene is not None:
            t = self._o3d.core.Tensor((flat - self.centre).astype(np.float32))
            d = self._scene.compute_signed_distance(t).numpy().astype(np.float64)
            # One ray misreads points whose ray grazes an edge (found: a point 9.8 mm outside the
            # cube's corner read as 9.8 mm inside); points read as inside are re-decided by a
            # majority of 3 rays (3x the cost, so only for them).
            inside = np.nonzero(d < 0)[0]
            if inside.size:
                t3 = self._o3d.core.Tensor((flat[inside] - self.centre).astype(np.float32))
                d[inside] = self._scene.compute_signed_distance(t3, nsamples=3).numpy().astype(np.float64)
        else:
            d = -trimesh.proximity.signed_distance(self.mesh, flat)
        return d.reshape(P.shape[:-1])


def _as_sdf(obj):
    """A signed-distance callable from a :class:`SignedDistance`, a mesh, or any callable
    mapping points (..., 3), metres, to signed distances (...), metres (positive outside)."""
    if isinstance(obj, SignedDistance) or (callable(obj) and not hasattr(obj, "vertices")):
        return obj
    return SignedDistance(obj)


# --- link box sampling -----------------------------------------------------------------------------
def box_surface_points(spec: ArmSpec, pitch_m: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Samples of one link's box surface in its own link frame.

    Every face of ``[0, L] x [-W/2, W/2] x [-H/2, H/2]`` gets a grid including its edges, with
    spacings of at most ``pitch_m`` (each side split into ``ceil(side / pitch)`` equal parts).

    Returns:
        points: (k, 3) metres, link frame (edge samples appear once per adjacent face).
        face: (k,) int, index into :data:`BOX_FACES` (inner = +y, outer = -y, top = +z,
            bottom = -z, proximal = x 0, distal = x L).
        cover_m: the covering radius: every point of the box surface is within this distance of
            a sample (the largest half-diagonal of a grid cell), metres.
    """
    if not (isinstance(pitch_m, (int, float)) and math.isfinite(pitch_m) and pitch_m > 0):
        raise ValueError(f"pitch_m must be a positive number of metres; got {pitch_m!r}")
    L, W, H = spec.link_length, spec.link_width, spec.link_height

    def axis(lo, hi):
        n = max(1, math.ceil((hi - lo) / pitch_m - 1e-9))
        return np.linspace(lo, hi, n + 1), (hi - lo) / n

    xs, dx = axis(0.0, L)
    ys, dy = axis(-W / 2, W / 2)
    zs, dz = axis(-H / 2, H / 2)
    pts, face = [], []

    def add(code, a, b, make):
        A, B = np.meshgrid(a, b, indexing="ij")
        pts.append(make(A.ravel(), B.ravel()))
        face.append(np.full(A.size, code))

    add(0, xs, zs, lambda x, z: np.stack([x, np.full_like(x, W / 2), z], -1))
    add(1, xs, zs, lambda x, z: np.stack([x, np.full_like(x, -W / 2), z], -1))
    add(2, xs, ys, lambda x, y: np.stack([x, y, np.full_like(x, H / 2)], -1))
    add(3, xs, ys, lambda x, y: np.stack([x, y, np.full_like(x, -H / 2)], -1))
    add(4, ys, zs, lambda y, z: np.stack([np.zeros_like(y), y, z], -1))
    add(5, ys, zs, lambda y, z: np.stack([np.full_like(y, L), y, z], -1))
    cover = 0.5 * max(math.hypot(dx, dz), math.hypot(dx, dy), math.hypot(dy, dz))
    return np.concatenate(pts), np.concatenate(face), cover


def _transform(T: np.ndarray, local: np.ndarray) -> np.ndarray:
    """(m, 4, 4) x (k, 3) -> (m, k, 3)."""
    return np.einsum("mij,kj->mki", T[:, :3, :3], local) + T[:, None, :3, 3]


def box_min_distance(spec: ArmSpec, T_world_link, sdf, cutoff_m: float = np.inf,
                     pitches_m=(5.0e-3, DETECTION_CONFIG_PITCH_M),
                     decide_only: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distance of link boxes to the object, coarse to fine.

    Every box is first bounded by the signed distance of its centre minus its circumradius, then
    sampled at each pitch of ``pitches_m`` in turn; a box leaves the refinement as soon as its
    lower bound (sampled minimum minus the grid's covering radius) exceeds ``cutoff_m``, since
    then it is certainly farther than the cutoff.  Boxes that may be within the cutoff are sampled
    at the finest pitch.

    Args:
        spec: the arm (box size).
        T_world_link: (m, 4, 4) link poses, world frame.
        sdf: a :class:`SignedDistance` (or a mesh).
        cutoff_m: the distance of interest, metres (np.inf: refine every box).
        pitches_m: increasing-resolution sampling pitches, metres.
        decide_only: also stop refining a box once its sampled minimum (an upper bound) is
            <= ``cutoff_m``: it is then known to be within the cutoff, which is all that
            "is it within?" questions need (its ``dist`` is then from a coarser grid).

    Returns:
        dist: (m,) metres: the sampled minimum signed distance over the box surface at the finest
            pitch the box reached (the centre distance minus the circumradius for boxes pruned
            before any sampling).
        err: (m,) metres: the true minimum lies in ``[dist - err, dist]`` (``err`` is the
            covering radius of the grid used; 0 for centre-bounded boxes, whose ``dist`` is
            itself a lower bound, so read those as ``dist`` <= true minimum).
        depth: (m,) metres >= 0: the deepest penetration of the sampled box surface into the
            object (0 for boxes certainly outside).
    """
    sdf = _as_sdf(sdf)
    T = np.asarray(T_world_link, dtype=np.float64).reshape(-1, 4, 4)
    m = T.shape[0]
    L, W, H = spec.link_length, spec.link_width, spec.link_height
    centres = T[:, :3, 3] + T[:, :3, 0] * (L / 2)
    dist = sdf(centres) - 0.5 * math.sqrt(L * L + W * W + H * H)
    err = np.zeros(m)
    depth = np.zeros(m)
    cut = max(float(cutoff_m), 0.0)
    active = np.flatnonzero(dist <= cut)
    for pitch in pitches_m:
        if active.size == 0:
            break
        local, _, cover = box_surface_points(spec, pitch)
        d = sdf(_transform(T[active], local))
        dmin = d.min(axis=1)
        dist[active], err[active] = dmin, cover
        depth[active] = np.maximum(0.0, -dmin)
        keep = dmin - cover <= cut
        if decide_only:
            keep &= dmin > cut
        active = active[keep]
    return dist, err, depth


def face_min_distance(spec: ArmSpec, T_world_link, sdf, face: str = "inner",
                      pitch_m: float = DETECTION_CONFIG_PITCH_M) -> np.ndarray:
    """(m,) minimum signed distance, metres, over one face (a name of :data:`BOX_FACES`) of each
    link box with pose ``T_world_link`` (m, 4, 4)."""
    if face not in BOX_FACES:
        raise ValueError(f"face must be one of {BOX_FACES}; got {face!r}")
    local, code, _ = box_surface_points(spec, pitch_m)
    local = local[code == BOX_FACES.index(face)]
    T = np.asarray(T_world_link, dtype=np.float64).reshape(-1, 4, 4)
    return _as_sdf(sdf)(_transform(T, local)).min(axis=1)


