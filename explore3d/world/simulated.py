"""The paper's simulated case (Fig. 10, Table I row "Simulated Cube").

The paper contrasts its 4-link robot with a simulation of "320 link positions of length
0.008 m" around the 80 mm square, "randomised rather than connected to each other", and
reports a 3.3 % area error at a = 0.2.  This module reproduces that experiment in 2D (shapely
polygons) and extends it to 3D (trimesh surfaces):

1. ``random_links_on_boundary`` lays straight links against the object: each touches the
   boundary at a uniformly random point and lies along the tangent there;
2. ``discretise_links`` turns each link into evenly spaced points (the paper's Fig. 1b);
3. ``simulated_case`` runs the inverse convex hull on those points and measures the error
   against the true shape (the paper's A_err / A_orig, eq. 6-7).

All coordinates are metres in the object's frame (the frame of the polygon or mesh passed in).
A link is stored as its two end points; the points are on the link's inner (object-side)
surface line, which is what the paper feeds to the inverse hull.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import shapely
import trimesh
from shapely.geometry import Polygon

from explore3d.core.defaults import PAPER_A
from explore3d.core.tolerances import SURFACE_ATOL_M
from explore3d.core.validate import check_positive
from explore3d.geometry.hull import InverseHull, inverse_hull
from explore3d.geometry.metrics import ShapeError, shape_error

__all__ = ["SimulatedCase", "discretise_links", "random_links_on_boundary", "simulated_case"]

#: Rejection sampling gives up after this many rounds of redrawing links that would penetrate
#: a concave object (each round redraws all still-missing links, twice over).
_MAX_ROUNDS = 200

#: For non-convex meshes a link is tested for penetration at this many evenly spaced points.
_PENETRATION_SAMPLES = 17


def random_links_on_boundary(shape, n_links: int, link_length: float, rng: np.random.Generator) -> np.ndarray:
    """Straight links of ``link_length`` metres laid against the boundary of ``shape``.

    Parameters
    ----------
    shape
        shapely Polygon (2D; its exterior ring is used, holes are cavities an arm wrapped
        around the object cannot reach) or closed trimesh.Trimesh (3D; its whole surface).
        Coordinates in metres.
    n_links
        Number of links, >= 1.
    link_length
        Link length in metres, > 0.
    rng
        numpy Generator; the only source of randomness.

    Returns
    -------
    (n_links, 2, d) float64 array, d = 2 or 3: start and end point of each link in metres, in
    the shape's frame.

    Each link touches the boundary at a point drawn uniformly by arc length (2D) or area
    (3D).  It lies along the tangent there: the edge direction (2D), or a uniformly random
    direction in the face plane (3D).  The touching point sits at a uniformly random position
    along the link.  For a convex shape the tangent line is a supporting line/plane, so the
    link never enters the object.  For a concave shape a tangent link can cut through the
    object (it runs past a reflex vertex or across a notch); such placements are physically
    impossible, so they are rejected and redrawn (touching point, direction and position
    together).  The accepted links are therefore uniform over the *feasible* placements, and
    regions narrower than a link (deep narrow notches) receive fewer or no links, as they would
    for a real arm.  In 2D the penetration test is exact (shapely, against the polygon shrunk by
    ``SURFACE_ATOL_M``); in 3D it checks ``_PENETRATION_SAMPLES`` points along the link with
    trimesh's signed distance, so a feature thinner than link_length/16 could be missed.
    Raises ValueError if almost no placement is feasible (links much longer than the shape's
    features).
    """
    n = int(n_links)
    if n != n_links or n < 1:
        raise ValueError(f"n_links must be an integer >= 1; got {n_links!r}")
    length = check_positive(link_length, "link_length")
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator (np.random.default_rng(seed)); got {type(rng).__name__}")

    if isinstance(shape, Polygon):
        draw, feasible = _sampler_2d(shape, length)
    elif isinstance(shape, trimesh.Trimesh):
        draw, feasible = _sampler_3d(shape, length)
    else:
        raise ValueError(f"shape must be a shapely Polygon (2D) or a trimesh.Trimesh (3D); got {type(shape).__name__}")

    kept: list[np.ndarray] = []
    missing = n
    drawn = 0
    for _ in range(_MAX_ROUNDS):
        batch = draw(rng, missing if not kept and drawn == 0 else 2 * missing)
        drawn += len(batch)
        ok = feasible(batch)
        good = batch[ok][:missing]
        kept.append(good)
        missing -= len(good)
        if missing == 0:
            return np.concatenate(kept, axis=0)
    raise ValueError(f"only {n - missing} of {n} links of {length} m could be laid against the shape without "
                     f"penetrating it after {drawn} draws; use shorter links")


def _sampler_2d(poly: Polygon, length: float):
    if poly.is_empty or not poly.is_valid or poly.area <= 0:
        raise ValueError("shape must be a valid, non-empty shapely Polygon with positive area")
    ring = np.asarray(poly.exterior.coords, dtype=np.float64)
    a, b = ring[:-1], ring[1:]
    edge = b - a
    edge_len = np.linalg.norm(edge, axis=1)
    keep = edge_len > 0
    a, edge, edge_len = a[keep], edge[keep], edge_len[keep]
    unit = edge / edge_len[:, None]
    prob = edge_len / edge_len.sum()
    convex = poly.convex_hull.area - poly.area <= SURFACE_ATOL_M * poly.length
    shrunk = poly.buffer(-SURFACE_ATOL_M)

    def draw(rng, m):
        e = rng.choice(len(a), size=m, p=prob)
        s = rng.random(m)
        t = rng.random(m)
        p = a[e] + s[:, None] * edge[e]
        u = unit[e]
        return np.stack([p - (t * length)[:, None] * u, p + ((1.0 - t) * length)[:, None] * u], axis=1)

    def feasible(seg):
        if convex:
            return np.ones(len(seg), dtype=bool)
        lines = shapely.linestrings(seg)
        return ~shapely.intersects(lines, shrunk)

    return draw, feasible


def _sampler_3d(mesh: trimesh.Trimesh, length: float):
    if len(mesh.faces) == 0 or not mesh.is_watertight or not mesh.volume > 0:
        raise ValueError("shape mesh must be a closed volume (watertight, outward wound); "
                         "load it with explore3d.world.objects.load_object to repair it")
    tri = np.asarray(mesh.triangles, dtype=np.float64)
    area = np.asarray(mesh.area_faces, dtype=np.float64)
    keep = area > 0
    tri, area = tri[keep], area[keep]
    normal = np.asarray(mesh.face_normals, dtype=np.float64)[keep]
    e1 = tri[:, 1] - tri[:, 0]
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    e2 = np.cross(normal, e1)
    prob = area / area.sum()
    convex = bool(mesh.is_convex)

    def draw(rng, m):
        f = rng.choice(len(tri), size=m, p=prob)
        u = rng.random(m)
        v = rng.random(m)
        flip = u + v > 1.0
        u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
        theta = rng.uniform(0.0, 2.0 * np.pi, size=m)
        t = rng.random(m)
        t0 = tri[f, 0]
        p = t0 + u[:, None] * (tri[f, 1] - t0) + v[:, None] * (tri[f, 2] - t0)
        d = np.cos(theta)[:, None] * e1[f] + np.sin(theta)[:, None] * e2[f]
        return np.stack([p - (t * length)[:, None] * d, p + ((1.0 - t) * length)[:, None] * d], axis=1)

    def feasible(seg):
        if convex:
            return np.ones(len(seg), dtype=bool)
        pts = discretise_links(seg, _PENETRATION_SAMPLES)
        depth = trimesh.proximity.signed_distance(mesh, pts)  # positive inside
        return (depth.reshape(len(seg), _PENETRATION_SAMPLES) <= SURFACE_ATOL_M).all(axis=1)

    return draw, feasible


def discretise_links(segments, points_per_link: int) -> np.ndarray:
    """Evenly spaced points along each link, both end points included.

    segments: (n, 2, d) start and end points in metres (any frame), d = 2 or 3.
    points_per_link: k >= 2.
    Returns (n * k, d) float64 points in the same frame, link-major: rows i*k .. i*k+k-1 are
    link i from its start to its end point (spacing link_length / (k - 1)).
    """
    seg = np.asarray(segments, dtype=np.float64)
    if seg.ndim != 3 or seg.shape[1] != 2 or seg.shape[2] not in (2, 3):
        raise ValueError(f"segments must have shape (n, 2, d) with d in (2, 3); got {seg.shape}")
    if not np.isfinite(seg).all():
        raise ValueError("segments must be finite")
    k = int(points_per_link)
    if k != points_per_link or k < 2:
        raise ValueError(f"points_per_link must be an integer >= 2 (both link ends); got {points_per_link!r}")
    w = np.linspace(0.0, 1.0, k)[None, :, None]
    pts = seg[:, None, 0, :] * (1.0 - w) + seg[:, None, 1, :] * w
    return pts.reshape(-1, seg.shape[2])


@dataclass(frozen=True, eq=False)
class SimulatedCase:
    """Result of ``simulated_case``; all coordinates in metres in the shape's frame.

    shape: the true object (shapely Polygon or trimesh.Trimesh).
    segments: (n_links, 2, d) link end points.
    points: (n_links * points_per_link, d) discretised link points fed to the inverse hull.
    hull: the InverseHull reconstruction.
    error: ShapeError of the reconstruction against ``shape`` (``error.percent`` is Table I's
    percentage error).
    """

    shape: object
    segments: np.ndarray = field(repr=False)
    points: np.ndarray = field(repr=False)
    hull: InverseHull = field(repr=False)
    error: ShapeError
    n_links: int
    link_length: float
    points_per_link: int
    a: float
    method: str
    centre: object
    seed: int


def simulated_case(shape, n_links: int = 320, link_length: float = 0.008, points_per_link: int = 5,
                   a: float = PAPER_A, method: str = "exponential", centre="mean", seed: int = 0) -> SimulatedCase:
    """Run the paper's simulated experiment on ``shape`` (Fig. 10, Table I "Simulated Cube").

    ``n_links`` random links of ``link_length`` metres are laid against ``shape`` (see
    ``random_links_on_boundary``, randomness from ``np.random.default_rng(seed)``), each is
    discretised into ``points_per_link`` evenly spaced points, the inverse hull with parameter
    ``a``, ``method`` and ``centre`` (default: mean of the link points, the paper's choice)
    reconstructs the object, and ``shape_error`` compares it with ``shape``.

    The defaults are the paper's numbers (320 links, 8 mm, a = 0.2).  The paper does not say
    how finely it discretised the links; 5 points per link (2 mm spacing, the link's ends and
    quarter points) is our choice.  On the 80 mm square the error hardly depends on it (links
    along an edge are collinear), see ``scripts/studies/parameter_study.py``.
    """
    k = int(points_per_link)
    rng = np.random.default_rng(seed)
    segments = random_links_on_boundary(shape, n_links, link_length, rng)
    points = discretise_links(segments, k)
    hull = inverse_hull(points, centre=centre, a=a, method=method)
    error = shape_error(hull, shape)
    return SimulatedCase(shape=shape, segments=segments, points=points, hull=hull, error=error,
                         n_links=int(n_links), link_length=float(link_length), points_per_link=k,
                         a=float(a), method=method, centre=centre, seed=seed)
