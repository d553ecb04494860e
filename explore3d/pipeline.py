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
        n_points_used: how many of ``exploration.points`` were within ``radius`` (the hull's input).
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


def reconstruct_exploration(ex: Exploration, centre, radius: float, a: float = 0.05, method: str = "exponential"):
    """Inverse hull of an exploration's points about the rough ``centre`` (3,), dropping points
    farther than ``radius`` metres from it.  Planar explorations use the x-y components."""
    from .hull import inverse_hull

    c = np.asarray(centre, dtype=float)[: ex.points.shape[1]]
    P = ex.points[within_bound(ex.points, centre, radius)]
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
    keep = within_bound(ex.points, centre, radius)
    try:
        hull = reconstruct_exploration(ex, centre, radius, a=a, method=method)
    except ValueError as exc:
        what = str(exc).split("; ")[0]  # inverse_hull's own fix hints are about its arguments, not the run
        raise ReconstructionError(
            f"no shape from the {int(keep.sum())} link points within {radius:.3g} m of the rough centre ({what}); "
            "explore from more directions or with more attempts (ExploreConfig directions/attempts, --directions/"
            "--attempts) so the arm surrounds the object, or correct the rough centre/radius", exploration=ex,
        ) from None
    truth = planar_truth(mesh, float(centre[2])) if config.mode == "planar" else mesh
    return Result(exploration=ex, hull=hull, truth=truth, error=shape_error(hull.shape(), truth, seed=seed),
                  centre=centre, radius=radius, n_points_used=int(keep.sum()))
