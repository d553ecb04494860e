"""Carving an estimate with the free space the arm swept through.

The inverse hull of the contacts is star-shaped about one centre and a hull of surface points
bridges every concavity the arm did not touch; but wherever a link passed, there is no object.
:func:`carve` removes from an estimate mesh the part of it that some wrap swept through
(:mod:`explore3d.reconstruction.freespace`): the estimate's volume is voxelised (``voxel_m``), voxels whose
centre is free are found, a morphological opening drops thin shells (free space grazing the
estimate's surface where the arm touched it: carving those would only roughen a right surface)
and what is left is cut out of the estimate with a mesh boolean (manifold3d).  Where nothing is
left to cut, the estimate comes back unchanged.  The slivers the cut leaves beside
the estimate's body are dropped and listed (:func:`explore3d.geometry.bodies.one_body`), and the
fins it leaves on it (thin walls of estimate between two carved regions, which a grasp planner
would take for surface and the Hausdorff distance for shape) are trimmed (:func:`trim_fins`).
Lengths in metres.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy import ndimage
from skimage.measure import marching_cubes

from explore3d.core.interrupt import import_optional
from explore3d.geometry.bodies import one_body
from explore3d.reconstruction.freespace import is_free

__all__ = ["CarveResult", "carve", "trim_fins", "DEFAULT_VOXEL_M", "DEFAULT_OPENING_VOXELS", "DEFAULT_FIN_M"]

#: voxel edge of the carving grid, m
DEFAULT_VOXEL_M = 1.0e-3
#: the opening's radius in voxels: free regions thinner than about 2 r + 1 voxels are not carved
DEFAULT_OPENING_VOXELS = 1
#: Gaussian smoothing (sigma, voxels) of the cut before marching cubes
SMOOTHING_VOXELS = 0.5
#: :func:`trim_fins`: parts of the carved estimate a ball of this radius cannot reach into (walls
#: thinner than twice it) that stand out of the rest by at least it are trimmed, m.  The links
#: are 20 mm wide and the carving grid 1 mm: no wall of a real object the arm can resolve is
#: thinner than 3 mm (measured on the default cube, noise seed 1: a fin 12.3 mm out of its face,
#: 1-3 mm thick, between two carved regions)
DEFAULT_FIN_M = 1.5e-3
#: the grid of :func:`trim_fins`, m (half the fin radius: on the default cube's five noise seeds
#: 0.5 and 0.6 mm trimmed the same fins to within 0.15 mm of Hausdorff distance, 3-4x slower)
FIN_VOXEL_M = 0.75e-3
#: the depth (times the fin radius) beyond which the opening's removal cannot be a rounded corner:
#: a cube corner loses sqrt(3) - 1 = 0.73 of the ball's radius, an edge sqrt(2) - 1 = 0.41
CORNER_DEPTH = math.sqrt(3.0) - 1.0

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CarveResult:
    """What :func:`carve` did.

    Attributes:
        mesh: the carved estimate (trimesh.Trimesh, metres).
        inside_m3: the estimate's volume as voxels, m^3.
        free_m3: of it, the volume swept free, m^3.
        carved_m3: the volume cut out (after the opening), m^3.
        dropped_m3: the volumes (m^3) of the slivers the cut left beside the estimate's body,
            dropped (:func:`explore3d.geometry.bodies.one_body`); empty when there were none.
        trimmed_m3: the volume of the fins trimmed off the carved estimate (:func:`trim_fins`), m^3.
    """

    mesh: object
    inside_m3: float
    free_m3: float
    carved_m3: float
    dropped_m3: tuple[float, ...] = ()
    trimmed_m3: float = 0.0


def _grid(bounds: np.ndarray, voxel_m: float):
    """Voxel centres on the world lattice ``(k + 1/2) voxel_m`` covering ``bounds`` (2, 3): the same
    voxels for estimates that differ by less than a voxel (e.g. a hull rebuilt from float32 points)."""
    lo, hi = bounds
    first = np.floor(lo / voxel_m - 0.5)
    n = np.maximum((np.ceil(hi / voxel_m - 0.5) - first).astype(int) + 1, 1)
    origin = (first + 0.5) * voxel_m
    axes = [origin[k] + voxel_m * np.arange(n[k]) for k in range(3)]
    return origin, n, axes


def _grid_points(bounds: np.ndarray, voxel_m: float):
    """:func:`_grid`'s origin (3,) and shape (3,) with its voxel centres as (m, 3) points, C order."""
    origin, n, axes = _grid(bounds, voxel_m)
    X, Y, Z = np.meshgrid(*axes, indexing="ij")
    return origin, n, np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])


def carve(mesh, areas, voxel_m: float = DEFAULT_VOXEL_M, opening_voxels: int = DEFAULT_OPENING_VOXELS,
          fin_m: float = DEFAULT_FIN_M) -> CarveResult:
    """Cut the swept free space (``areas``: :class:`~explore3d.reconstruction.freespace.SweptArea` list) out of
    the closed estimate ``mesh`` (trimesh, metres) and trim the fins the cut leaves thinner than
    ``2 fin_m`` (:func:`trim_fins`; 0: none); see the module docstring."""

    if voxel_m <= 0:
        raise ValueError(f"voxel_m must be > 0; got {voxel_m}")
    if not isinstance(opening_voxels, int) or opening_voxels < 0:
        raise ValueError(f"opening_voxels must be an integer >= 0; got {opening_voxels!r}")
    if not fin_m >= 0:
        raise ValueError(f"fin_m must be >= 0 (metres; 0 trims nothing); got {fin_m!r}")
    origin, n, centres = _grid_points(np.asarray(mesh.bounds, dtype=float), voxel_m)
    inside = _contains(mesh, centres)
    free = np.zeros(len(centres), dtype=bool)
    free[inside] = is_free(areas, centres[inside])
    vol = voxel_m ** 3
    unchanged = CarveResult(mesh=mesh, inside_m3=inside.sum() * vol, free_m3=free.sum() * vol, carved_m3=0.0)
    cut = free.reshape(n)
    if opening_voxels:
        cut = ndimage.binary_opening(cut, structure=ndimage.generate_binary_structure(3, 3),
                                     iterations=opening_voxels)
    if not cut.any():
        return unchanged

    cut, outside = _reach_outside(cut, inside.reshape(n))
    try:
        out = mesh.difference(_cut_tool(cut, origin, voxel_m), engine="manifold")
    except ValueError as exc:  # the tool is not a closed volume: keep the estimate uncarved, say so
        log.warning("carving skipped: the swept free space gave no closed cutting volume (%s)", exc)
        return unchanged
    carved = float((cut[1:-1, 1:-1, 1:-1] & ~outside[1:-1, 1:-1, 1:-1]).sum()) * vol
    out, dropped = one_body(out)
    trimmed = 0.0
    if fin_m > 0:
        out, trimmed = trim_fins(out, fin_m)
    return dataclasses.replace(unchanged, mesh=out, carved_m3=carved, dropped_m3=dropped, trimmed_m3=trimmed)


def _reach_outside(cut: np.ndarray, inside: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The voxels ``cut`` (a grid's, bool) padded by one voxel and reaching one voxel beyond the
    estimate (``inside``, the same grid) where they meet its surface, so the boolean leaves no skin
    on its faces (the space outside is cut for nothing); and the padded outside."""
    cut = np.pad(cut, 1)
    outside = np.pad(~inside, 1, constant_values=True)
    cut |= ndimage.binary_dilation(cut, structure=ndimage.generate_binary_structure(3, 1)) & outside
    return cut, outside


def _cut_tool(cut: np.ndarray, origin: np.ndarray, voxel_m: float):
    """The closed cutting volume (trimesh) of the voxels ``cut`` (a grid padded by one voxel on
    every side of the lattice at ``origin``, m), by marching cubes."""
    # marching cubes on the voxels smoothed by half a voxel: on the raw 0/1 field it gave
    # non-manifold edges where voxels meet along an edge (measured on the cross prism's carve; a
    # boolean then refuses the tool); smoothed, the surface moves by well under a voxel
    field = ndimage.gaussian_filter(np.pad(cut, 1).astype(np.float32), SMOOTHING_VOXELS)
    verts, faces, _, _ = marching_cubes(field, level=0.5, spacing=(voxel_m,) * 3)
    tool = trimesh.Trimesh(verts + (origin - 2 * voxel_m), faces[:, ::-1], process=True)
    if tool.volume < 0:
        tool.invert()
    return tool


def trim_fins(mesh, fin_m: float = DEFAULT_FIN_M, voxel_m: float = FIN_VOXEL_M) -> tuple[object, float]:
    """``mesh`` (closed trimesh, metres) without its fins, and the volume trimmed, m^3.

    A fin is a part of the body a ball of radius ``fin_m`` cannot reach into (the body's
    morphological opening by that ball on a ``voxel_m`` grid leaves it out) that stands at least
    ``fin_m`` out of what the ball reaches: a thin wall or spike.  What the opening only rounds off
    (a convex edge or corner loses less than ``fin_m`` of depth) is kept, so faces and edges stay
    as they are.  Trimming only removes volume: the result never enters space ``mesh`` leaves
    free (the carved free space in particular).  ``mesh`` itself comes back when it has no fin."""
    if not fin_m > 0 or not voxel_m > 0:
        raise ValueError(f"fin_m and voxel_m must be > 0 (metres); got {fin_m!r} and {voxel_m!r}")
    origin, n, centres = _grid_points(np.asarray(mesh.bounds, dtype=float) + [[-2 * fin_m], [2 * fin_m]], voxel_m)
    inside = _contains(mesh, centres).reshape(n)
    r = int(math.ceil(fin_m / voxel_m - 1e-9))
    g = np.indices((2 * r + 1,) * 3) - r
    ball = (g ** 2).sum(0) <= r * r
    reached = ndimage.binary_opening(inside, structure=ball)
    thin = inside & ~reached
    if not thin.any():
        return mesh, 0.0
    depth = ndimage.distance_transform_edt(~reached) * voxel_m  # how far each voxel lies from the reached body
    # what the opening rounds off a convex edge or corner lies within (sqrt(3) - 1) fin_m of the
    # reached body: only deeper voxels (and the layer under them) can be a fin's, so the shells
    # along the edges, connected to a fin, are not cut with it
    core = thin & (depth > CORNER_DEPTH * fin_m)
    core |= ndimage.binary_dilation(core, structure=ndimage.generate_binary_structure(3, 3)) & thin
    labels, k = ndimage.label(core, structure=ndimage.generate_binary_structure(3, 3))
    if not k:
        return mesh, 0.0
    deepest = np.asarray(ndimage.maximum(depth, labels, index=np.arange(1, k + 1)))
    fins = np.isin(labels, 1 + np.flatnonzero(deepest >= fin_m))
    if not fins.any():
        return mesh, 0.0
    cut, _ = _reach_outside(fins, inside)
    try:
        out = mesh.difference(_cut_tool(cut, origin, voxel_m), engine="manifold")
    except ValueError as exc:
        log.warning("fins kept: their voxels gave no closed cutting volume (%s)", exc)
        return mesh, 0.0
    out, _ = one_body(out)
    merged = out.copy()
    merged.merge_vertices()  # as a mesh file read back is: the cut's near-coincident vertices joined
    if not (out.is_watertight and merged.is_watertight and out.volume > 0):
        log.info("fins kept: trimming them left no closed body once its vertices are merged")
        return mesh, 0.0
    trimmed = float(fins.sum()) * voxel_m ** 3
    log.info("trimmed %d fin(s), %.3g m^3, from the carved estimate", int(np.count_nonzero(deepest >= fin_m)), trimmed)
    return out, trimmed


def _contains(mesh, points: np.ndarray) -> np.ndarray:
    """Inside test of a closed mesh: open3d's occupancy when installed (measured about 8x faster),
    else trimesh's ray test (Embree when embreex is installed)."""
    try:
        o3d = import_optional("open3d")
    except (ImportError, OSError):  # an interrupted import raises KeyboardInterrupt instead
        return np.asarray(mesh.contains(points), dtype=bool)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
                        o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)))
    occ = scene.compute_occupancy(o3d.core.Tensor(points.astype(np.float32)))
    return occ.numpy().astype(bool)
