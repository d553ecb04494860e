"""Estimators for shapes that are not star-shaped about one centre (issue 11, item 5).

The paper's estimate is the inverse hull of the contacts about the rough centre: a surface star-
shaped about that centre, so any surface hidden from it (a U-channel's slot walls seen from a
centre in the slot, a notch's far side) cannot be represented, and :func:`~explore3d.reconstruction.
hull_input.hull_input_mask` drops such contacts as outliers.  Three alternatives on the same contacts and
free space, each a closed mesh (trimesh, metres, world frame):

* :func:`convex_carved`: the convex hull of the contacts, carved by the swept free space
  (:func:`explore3d.reconstruction.carve.carve`): everything not swept is kept.
* :func:`multi_centre`: inverse hulls of *all* the contacts about several centres inside the
  single-centre carved estimate (the deepest points of its voxels, farthest-point spread), united
  and carved.  Each is star-shaped about its own centre; the union is not.
* :func:`implicit_surface`: a signed distance fitted to the contacts and their normals (Hoppe et
  al. 1992: the distance to the tangent plane of the nearest contacts, normals pointing out of the
  object, as :class:`~explore3d.feeling.contacts.ContactSet` gives them), positive (outside) wherever the
  arm swept, its zero set extracted by marching cubes inside the rough bound; voxels farther than
  ``reach_m`` from every contact take the carved single-centre estimate's inside/outside.

Pure functions on numpy arrays; lengths in metres.  The paper's inverse hull stays the default
(``explore3d reconstruct``'s and the pipeline's); scripts/studies/estimator_study.py measures these.
"""
from __future__ import annotations

import numpy as np
import trimesh
from scipy import ndimage
from scipy.spatial import cKDTree
from skimage.measure import marching_cubes

from explore3d.core.defaults import DEFAULT_A, ESTIMATOR_NAMES
from explore3d.geometry.hull import inverse_hull
from explore3d.reconstruction.carve import _contains, _grid_points, carve
from explore3d.reconstruction.freespace import is_free
from explore3d.reconstruction.hull_input import reconstruct_points, within_bound

__all__ = ["ESTIMATORS", "estimate", "single_centre", "convex_carved", "multi_centre", "implicit_surface", "interior_centres"]


def _carve(mesh, swept):
    """``mesh`` carved by ``swept``, its fins kept (``fin_m=0``): these estimators also aim the
    probe rounds (:func:`explore3d.strategy.explore.current_estimate`), whose targets and figures
    were measured on the untrimmed carving; the run's final estimate is trimmed
    (:func:`explore3d.app.pipeline.estimate_exploration`)."""
    return carve(mesh, swept, fin_m=0.0).mesh if swept else mesh


def single_centre(points, wrap, centre, radius: float, swept=(), a: float = DEFAULT_A):
    """The pipeline's estimate: the inverse hull about the rough ``centre`` (3,) of the ``points``
    (m, 3) that :func:`~explore3d.reconstruction.hull_input.hull_input_mask` keeps (``wrap`` (m,) ids), carved."""
    return _carve(reconstruct_points(points, wrap, centre, radius, a=a).mesh, swept)


def convex_carved(points, centre, radius: float, swept=()):
    """Convex hull of the ``points`` (m, 3) within ``radius`` of ``centre``, carved by ``swept``."""
    P = np.asarray(points, dtype=float)
    return _carve(trimesh.convex.convex_hull(P[within_bound(P, centre, radius)]), swept)


def _voxels(mesh, voxel_m: float):
    """Inside mask (nx, ny, nz) of ``mesh`` on the carving lattice, and the lattice's origin (3,)."""
    origin, n, centres = _grid_points(np.asarray(mesh.bounds, dtype=float), voxel_m)
    return _contains(mesh, centres).reshape(n), origin


def interior_centres(mesh, n: int = 6, voxel_m: float = 2.0e-3, min_depth_fraction: float = 0.4) -> np.ndarray:
    """(k, 3), k <= n: points deep inside the closed ``mesh``: voxels whose distance to the outside
    is at least ``min_depth_fraction`` of the deepest's, spread by farthest-point sampling from the
    deepest (each next centre the one farthest from those chosen)."""
    inside, origin = _voxels(mesh, voxel_m)
    depth = ndimage.distance_transform_edt(np.pad(inside, 1))[1:-1, 1:-1, 1:-1]
    if depth.max() <= 0:
        raise ValueError("the estimate has no voxel inside it: no interior centre; use a smaller voxel_m")
    idx = np.argwhere(depth >= min_depth_fraction * depth.max())
    P = origin + idx * voxel_m
    chosen = [int(np.argmax(depth[tuple(idx.T)]))]
    d = np.linalg.norm(P - P[chosen[0]], axis=1)
    while len(chosen) < n and d.max() > 2 * voxel_m:
        chosen.append(int(np.argmax(d)))
        d = np.minimum(d, np.linalg.norm(P - P[chosen[-1]], axis=1))
    return P[chosen]


def multi_centre(points, wrap, centre, radius: float, swept=(), a: float = DEFAULT_A, n_centres: int = 6):
    """Union of the inverse hulls of all ``points`` within ``radius`` of ``centre`` about
    :func:`interior_centres` of the carved single-centre estimate, carved by ``swept``."""

    P = np.asarray(points, dtype=float)
    P = P[within_bound(P, centre, radius)]
    base = single_centre(points, wrap, centre, radius, swept, a=a)
    parts = []
    for c in interior_centres(base, n_centres):
        try:
            parts.append(inverse_hull(P, centre=c, a=a).mesh)
        except ValueError:  # a centre outside the points' hull, or on one of them: no hull about it
            continue
    if not parts:
        return base
    union = parts[0] if len(parts) == 1 else trimesh.boolean.union(parts, engine="manifold")
    return _carve(union, swept)


def implicit_surface(points, normals, wrap, centre, radius: float, swept=(), a: float = DEFAULT_A,
                     voxel_m: float = 1.5e-3, k: int = 8, reach_m: float = 0.015):
    """Zero set of a signed distance fitted to the contacts, their outward ``normals`` (m, 3) and the
    swept free space (see the module docstring)."""


    P = np.asarray(points, dtype=float)
    N = np.asarray(normals, dtype=float)
    keep = within_bound(P, centre, radius)
    P, N = P[keep], N[keep] / np.linalg.norm(N[keep], axis=1, keepdims=True)
    base = single_centre(points, wrap, centre, radius, swept, a=a)
    lo = np.minimum(P.min(axis=0), base.bounds[0]) - 3 * voxel_m
    hi = np.maximum(P.max(axis=0), base.bounds[1]) + 3 * voxel_m
    origin, n, G = _grid_points(np.array([lo, hi]), voxel_m)
    dist, nn = cKDTree(P).query(G, k=min(k, len(P)))
    dist, nn = dist.reshape(len(G), -1), nn.reshape(len(G), -1)
    w = 1.0 / np.maximum(dist, voxel_m) ** 2
    plane = np.einsum("gkd,gkd->gk", G[:, None, :] - P[nn], N[nn])
    f = (w * plane).sum(axis=1) / w.sum(axis=1)
    far = dist[:, 0] > reach_m
    inside_base = _contains(base, G)
    f[far] = np.where(inside_base[far], -voxel_m, voxel_m)
    if swept:
        free = is_free(swept, G)
        f[free] = np.maximum(f[free], voxel_m)
    f = f.reshape(n)
    # the largest connected inside piece: stray planes' extrapolation leaves specks
    lab, m = ndimage.label(f < 0)
    if m == 0:
        return base
    sizes = ndimage.sum(f < 0, lab, range(1, m + 1))
    piece = ndimage.binary_dilation(lab == (1 + int(np.argmax(sizes))), iterations=2)
    f = np.where(piece, f, np.maximum(f, voxel_m))
    # marching cubes on the signed distance itself: its zero set lies between the voxel centres
    # (a plane comes back flat, not rounded to the voxels)
    field = np.pad(f, 1, constant_values=voxel_m)
    verts, faces, _, _ = marching_cubes(field, level=0.0, spacing=(voxel_m,) * 3)
    mesh = trimesh.Trimesh(verts + (origin - voxel_m), faces, process=True)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


#: the estimators' names (``explore3d reconstruct --estimator``), the paper's first (defined in the
#: light :mod:`explore3d.core.defaults`, which ``explore3d --help`` imports without numpy)
ESTIMATORS = ESTIMATOR_NAMES


def estimate(name: str, points, wrap, centre, radius: float, swept=(), a: float = DEFAULT_A, normals=None):
    """The closed estimate (trimesh, metres) of estimator ``name`` (:data:`ESTIMATORS`) from contact
    ``points`` (m, 3) with their ``wrap`` ids (m,), the rough ``centre`` (3,) and ``radius`` (m),
    the swept free space ``swept`` (:class:`~explore3d.reconstruction.freespace.SweptArea` list) and, for
    ``implicit``, the contacts' outward ``normals`` (m, 3)."""
    if name not in ESTIMATORS:
        raise ValueError(f"estimator must be one of {ESTIMATORS}; got {name!r}")
    if name == "inverse-hull":
        return single_centre(points, wrap, centre, radius, swept, a=a)
    if name == "convex-carved":
        return convex_carved(points, centre, radius, swept)
    if name == "multi-centre":
        return multi_centre(points, wrap, centre, radius, swept, a=a)
    if normals is None:
        raise ValueError("the implicit estimator needs the contacts' normals (m, 3): a run's points.ply of "
                         "localised contacts (the default) carries them as nx, ny, nz")
    return implicit_surface(points, normals, wrap, centre, radius, swept, a=a)
