"""Explore, reconstruct and score in one call: the library's main entry point.

``reconstruct_exploration`` uses only what the robot knows: the link surface points, the rough
centre it was told (as the inversion centre) and the rough bounding radius (points beyond it
cannot lie on the object and are dropped).  Scoring against the true shape happens afterwards.
The command line's ``explore3d run`` calls :func:`run`, so both give the same estimate for the
same configuration.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .explore import Exploration, ExploreConfig, explore, rough_bound


@dataclass(frozen=True)
class Result:
    """An exploration, its reconstruction and its score.

    Attributes:
        exploration: what the arm gathered.
        hull: the :class:`~explore3d.hull.InverseHull` (2D planar, 3D otherwise), world frame.
        truth: the true shape (shapely Polygon planar, trimesh 3D), world frame.
        error: :class:`~explore3d.metrics.ShapeError` of ``hull`` against ``truth``.
        centre: (3,) the robot's rough centre, world frame, metres (the inversion centre; planar
            runs use its x-y components and cut the truth at its z).
        radius: the robot's rough bounding radius, metres: points farther than this from
            ``centre`` were dropped before the hull.
        n_points_used: how many of ``exploration.points`` the hull was built from (within ``radius``,
            not angular outliers: :func:`hull_input_mask`).
    """

    exploration: Exploration
    hull: object
    truth: object
    error: object
    centre: np.ndarray
    radius: float = math.nan
    n_points_used: int = -1

    @property
    def estimate(self):
        """The reconstructed shape: shapely Polygon (planar) or closed trimesh (3D), world frame, metres."""
        return self.hull.shape()

    def summary(self) -> dict:
        """The figures of a run as a JSON-ready dict: :func:`exploration_summary`, ``n_points_used``,
        ``percent_error``, ``iou``, ``chamfer_m``, ``hausdorff_m``, ``true_size``, ``estimate_size``
        (m^2 planar, m^3 3D; ``size_unit``), ``centre_m`` and ``radius_m`` (the rough bound), and
        ``estimate_convex_hull``: the estimate's convex hull ``size`` (m^2 / m^3) and ``centre_m``
        (its centroid, world frame), what a grasp planner takes as the object's extent."""
        e = self.error
        est = self.estimate
        if e.dim == 2:
            ch = est.convex_hull
            hull = {"size": float(ch.area), "centre_m": [float(ch.centroid.x), float(ch.centroid.y)]}
        else:
            ch = est.convex_hull
            hull = {"size": float(ch.volume), "centre_m": [float(x) for x in ch.center_mass]}
        return {**exploration_summary(self.exploration), "n_points_used": self.n_points_used,
                "estimate_convex_hull": hull,
                "percent_error": e.percent, "iou": e.iou, "chamfer_m": e.chamfer_m, "hausdorff_m": e.hausdorff_m,
                "true_size": e.true_size, "estimate_size": e.estimate_size,
                "size_unit": "m^2" if e.dim == 2 else "m^3",
                "centre_m": [float(x) for x in self.centre], "radius_m": float(self.radius)}


def exploration_summary(ex: Exploration) -> dict:
    """``n_wraps``, ``n_points``, ``n_contacts``, ``wall_s``, ``sim_s`` and ``steps`` of an exploration."""
    return {"n_wraps": ex.n_wraps, "n_points": int(len(ex.points)), "n_contacts": ex.n_contacts,
            "wall_s": float(ex.wall_s), "sim_s": float(ex.sim_time_s), "steps": int(ex.steps)}


def write_result(result: Result, mesh, out, fmt: str = "obj", pictures: bool = True) -> list[str]:
    """Write a run's files into folder ``out`` (created) and return their names:

    * ``estimate.<fmt>`` (obj, stl, ply, off, glb): the estimate mesh, world frame, metres; planar
      runs: the polygon extruded over ``mesh``'s z range; ``estimate.urdf`` loading it in PyBullet
      (plus ``estimate.obj`` when ``fmt`` is not obj/stl);
    * ``estimate_polygon.json`` (planar): the polygon as a list of [x, y], metres, counter-clockwise;
    * ``points.ply``: the link points with their wrap, attempt and link;
    * ``figure.png``/``views.png``, ``overview.png``, ``scene.png`` with ``pictures=True``.

    ``mesh`` is the explored object (closed trimesh, metres).  Files are written atomically.
    """
    import json
    from pathlib import Path

    import trimesh

    from .export import check_format, write_estimate_urdf, write_mesh, write_points_ply
    from .io import atomic_write_text

    fmt = check_format(fmt)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    ex, estimate = result.exploration, result.estimate
    write_points_ply(ex.points, out / "points.ply", ex.point_wrap, ex.point_attempt, ex.point_link)
    names = ["points.ply"]
    if ex.config.mode == "planar":
        ring = [[float(x), float(y)] for x, y in list(estimate.exterior.coords)[:-1]]
        atomic_write_text(out / "estimate_polygon.json", json.dumps(ring, indent=2) + "\n")
        names.append("estimate_polygon.json")
        zlo, zhi = mesh.bounds[:, 2]
        est_mesh = trimesh.creation.extrude_polygon(estimate, float(zhi - zlo))
        est_mesh.apply_translation([0.0, 0.0, float(zlo)])
    else:
        est_mesh = estimate
    mesh_name = f"estimate.{fmt}"
    write_mesh(est_mesh, out / mesh_name, fmt)
    write_estimate_urdf(mesh_name, out / "estimate.urdf", mesh=est_mesh)
    names += [mesh_name, "estimate.urdf"] + ([] if fmt in ("obj", "stl") else ["estimate.obj"])  # PyBullet's copy
    if pictures:
        from . import pictures as pics

        names += pics.run_pictures(out, ex, estimate, result.truth, mesh, result.error)
    return sorted(names)


class NoContactError(RuntimeError):
    """The exploration detected no contact at all.  ``exploration`` holds what was gathered
    (None if unknown), so callers can still report the wraps that were run."""

    def __init__(self, message: str, exploration: Exploration | None = None):
        super().__init__(message)
        self.exploration = exploration


class ReconstructionError(ValueError):
    """The points of an exploration did not give a hull (too few, degenerate, or not around the
    rough centre).  ``exploration`` holds what was gathered."""

    def __init__(self, message: str, exploration: Exploration | None = None):
        super().__init__(message)
        self.exploration = exploration


def within_bound(points, centre, radius: float) -> np.ndarray:
    """(m,) bool mask of ``points`` (m, d), metres, no farther than ``radius`` metres from the
    rough ``centre`` (3,) (its first d components)."""
    P = np.asarray(points, dtype=float)
    c = np.asarray(centre, dtype=float)[: P.shape[1]]
    return np.linalg.norm(P - c, axis=1) <= radius


#: A point is an outlier when its distance from the centre is below this fraction of the median
#: distance of its angular neighbours from *other* wraps (see :func:`angular_outliers`).
OUTLIER_RATIO = 0.5


def angular_outliers(points, centre, groups, ratio: float = OUTLIER_RATIO, k: int = 16) -> np.ndarray:
    """(m,) bool mask of points (m, d), metres, far *inside* what the other wraps saw in the same
    direction: distance from ``centre`` (d,) below ``ratio`` x the median distance of its angular
    neighbours (up to 4k nearest directions) that come from other ``groups`` (m,) (wraps).

    The inverse hull keeps every point nearer the centre than its surroundings, so one link that
    ended up inside the object would carve a deep pit.  Measured: in one of 144 3D wraps around the
    50 mm sphere two links passed through PyBullet's surface-only triangle mesh and stopped 8-12 mm
    from the centre; the volume error went from 8% to 35%.  A wrap cannot vouch for itself, so
    only other wraps' points count as neighbours; points without such neighbours are kept.
    """
    from scipy.spatial import cKDTree

    P = np.asarray(points, dtype=float)
    g = np.asarray(groups)
    d = P.shape[1]
    V = P - np.asarray(centre, dtype=float)[:d]
    r = np.linalg.norm(V, axis=1)
    out = np.zeros(len(P), dtype=bool)
    if len(P) < 2:
        return out
    u = V / np.maximum(r, 1e-12)[:, None]
    kq = min(len(P), 4 * k)
    _, idx = cKDTree(u).query(u, k=kq)
    idx = idx.reshape(len(P), -1)
    rn = np.where(g[idx] != g[:, None], r[idx], np.nan)
    has = np.isfinite(rn).any(axis=1)
    med = np.full(len(P), np.nan)
    med[has] = np.nanmedian(rn[has], axis=1)
    out[has] = r[has] < ratio * med[has]
    return out


def hull_input_mask(ex: Exploration, centre, radius: float, outlier_ratio: float | None = OUTLIER_RATIO) -> np.ndarray:
    """(m,) bool mask of the exploration's points the reconstruction uses: within ``radius`` metres
    of the rough ``centre`` and, unless ``outlier_ratio`` is None, not an :func:`angular_outliers`."""
    keep = within_bound(ex.points, centre, radius)
    if outlier_ratio is not None and keep.any():
        idx = np.nonzero(keep)[0]
        keep[idx[angular_outliers(ex.points[idx], centre, ex.point_wrap[idx], outlier_ratio)]] = False
    return keep


def reconstruct_exploration(ex: Exploration, centre, radius: float, a: float = 0.05, method: str = "exponential",
                            outlier_ratio: float | None = OUTLIER_RATIO):
    """Inverse hull of an exploration's points about the rough ``centre`` (3,), dropping points
    farther than ``radius`` metres from it and points far inside what other wraps saw in the same
    direction (:func:`hull_input_mask`).  Planar explorations use the x-y components."""
    from .hull import inverse_hull

    c = np.asarray(centre, dtype=float)[: ex.points.shape[1]]
    P = ex.points[hull_input_mask(ex, centre, radius, outlier_ratio)]
    return inverse_hull(P, centre=c, a=a, method=method)


def planar_truth(mesh, z: float):
    """The true 2D shape of the planar case: the mesh's cross-section at height ``z`` metres
    (x-y, world frame, metres).

    A mesh of several bodies (convex decompositions such as pybullet_data's ``*_vhacd.obj`` have
    touching or overlapping pieces, whose joint section trimesh gets wrong) is cut body by body:
    the union of the sections of positive-volume bodies minus those of inward-wound ones (cavities).
    """
    from shapely.ops import unary_union

    from .objects import cross_section

    bodies = mesh.split(only_watertight=False) if mesh.body_count > 1 else [mesh]
    if len(bodies) == 1:
        return cross_section(mesh, z=z)
    solid, cavities = [], []
    for body in bodies:
        zlo, zhi = body.bounds[:, 2]
        if zlo < z < zhi:
            (solid if body.volume > 0 else cavities).append(cross_section(body, z=z))
    if not solid:
        return cross_section(mesh, z=z)  # raises: the plane misses the mesh
    region = unary_union(solid)
    return region.difference(unary_union(cavities)) if cavities else region


def rough_bound_or(mesh, centre=None, radius=None) -> tuple[np.ndarray, float]:
    """The robot's rough centre (3,) and radius (m): the given ones, checked, else
    :func:`~explore3d.explore.rough_bound` of the mesh's vertices."""
    from ._validate import check_positive, check_vector

    c0, r0 = rough_bound(mesh.vertices)
    c = c0 if centre is None else check_vector(centre, "centre (the rough object centre x, y, z in metres)", 3)
    r = r0 if radius is None else check_positive(radius, "radius (the rough bounding radius in metres)")
    return c, r


def run(mesh, arm="default", config: ExploreConfig = ExploreConfig(), a: float = 0.05,
        method: str = "exponential", progress=None, *, centre=None, radius=None, seed: int = 0) -> Result:
    """Explore ``mesh`` (closed trimesh, metres) with ``arm``, reconstruct, and score.

    Args:
        mesh: the object (given to the simulated world only).
        arm: built-in arm name, URDF path or :class:`~explore3d.arm.ArmSpec`.
        config: how to explore.
        a: inverse-hull coarseness > 0; method: "exponential" or "spherical".
        progress: None, or ``progress(done, total)`` called after each wrap.
        centre, radius: the rough location (3,), world frame, metres, and bounding radius (m) the
            robot is told (the user's rough bound of where the object is).  Default: the
            bounding-box centre of ``mesh`` and 1.05 times its largest vertex distance from it
            (:func:`~explore3d.explore.rough_bound`).
        seed: seed of the surface samples of the Chamfer/Hausdorff measures (3D).

    Raises:
        NoContactError: the arm touched nothing (the object is out of reach or too big).
        ReconstructionError: the contact points gave no hull (a ValueError).
    """
    from .metrics import shape_error

    centre, radius = rough_bound_or(mesh, centre, radius)
    ex = explore(mesh, arm, config, centre=centre, radius=radius, progress=progress)
    if ex.n_contacts == 0:
        raise NoContactError(
            "the arm made no contact with the object: it is out of reach, too large for the arm, or the rough "
            "centre/radius is wrong; use a longer arm (arm=, --arm), a smaller object (load_object(size=), --size) "
            "or a correct rough bound (centre=/radius=, --centre/--radius)",
            exploration=ex,
        )
    try:
        hull = reconstruct_exploration(ex, centre, radius, a=a, method=method)
    except ValueError as exc:
        what = str(exc).split("; ")[0]  # inverse_hull's own fix hints are about its arguments, not the run
        n_used = int(hull_input_mask(ex, centre, radius).sum())
        raise ReconstructionError(
            f"no shape from the {n_used} link points within {radius:.3g} m of the rough centre ({what}); "
            "explore from more directions or with more attempts (ExploreConfig directions/attempts, --directions/"
            "--attempts) so the arm surrounds the object, or correct the rough centre/radius", exploration=ex,
        ) from None
    truth = planar_truth(mesh, float(centre[2])) if config.mode == "planar" else mesh
    return Result(exploration=ex, hull=hull, truth=truth, error=shape_error(hull.shape(), truth, seed=seed),
                  centre=centre, radius=radius, n_points_used=len(hull.points))  # the hull's input
