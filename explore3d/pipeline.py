"""Explore, reconstruct and score in one call: the library's main entry point.

``reconstruct_exploration`` uses only what the robot knows: the link surface points, the rough
centre it was told (as the inversion centre) and the rough bounding radius (points beyond it
cannot lie on the object and are dropped).  Scoring against the true shape happens afterwards.
"""
from __future__ import annotations

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
        centre: (d,) the inversion centre (the robot's rough centre), metres.
    """

    exploration: Exploration
    hull: object
    truth: object
    error: object
    centre: np.ndarray


def reconstruct_exploration(ex: Exploration, centre, radius: float, a: float = 0.05, method: str = "exponential"):
    """Inverse hull of an exploration's points about the rough ``centre`` (3,), dropping points
    farther than ``radius`` metres from it.  Planar explorations use the x-y components."""
    from .hull import inverse_hull

    c = np.asarray(centre, dtype=float)
    c = c[: ex.points.shape[1]]
    P = ex.points[np.linalg.norm(ex.points - c, axis=1) <= radius]
    return inverse_hull(P, centre=c, a=a, method=method)


def planar_truth(mesh, z: float):
    """The true 2D shape of the planar case: the mesh's cross-section at height ``z`` metres."""
    from .objects import cross_section

    return cross_section(mesh, z=z)


def run(mesh, arm="default", config: ExploreConfig = ExploreConfig(), a: float = 0.05,
        method: str = "exponential", progress=None) -> Result:
    """Explore ``mesh`` (closed trimesh, metres) with ``arm``, reconstruct, and score."""
    from .metrics import shape_error

    centre, radius = rough_bound(mesh.vertices)
    ex = explore(mesh, arm, config, centre=centre, radius=radius, progress=progress)
    if ex.n_contacts == 0:
        raise NoContactError(
            "the arm made no contact with the object: it is too far or too large for the arm; "
            "use a longer arm (--arm) or a smaller object (--size)"
        )
    hull = reconstruct_exploration(ex, centre, radius, a=a, method=method)
    truth = planar_truth(mesh, float(centre[2])) if config.mode == "planar" else mesh
    return Result(exploration=ex, hull=hull, truth=truth, error=shape_error(hull.shape(), truth), centre=centre)


class NoContactError(RuntimeError):
    """The exploration detected no contact at all."""
