"""The inverse convex hull: the shape implied by the absence of link positions.

A blind arm wrapped around an object leaves contact points on (and outside) the object's
surface.  Seen from a centre inside the object, the points *closest* to the centre along each
direction outline the object.  The inverse convex hull finds them: every point is moved along
its own ray from the centre so that near points become far ones ("inversion"), the ordinary
convex hull of the moved points is taken, and its vertices and triangles are mapped back onto
the original points (paper section II, eqs. (3)-(5); Katz, Tal & Basri 2007; Katz & Tal 2015).

Frames: every array is in the caller's frame (any frame, metres); nothing is transformed
except by the inversion itself, which works on ``points - centre``.  The result indexes the
original points, so shapes come out in the input frame.

Why not the paper's formula as printed.  The paper writes ``d_i(a) = r_i**-a`` and
``P_inv = d_i(a) * P_i``.  Taken literally, ``|P_inv| = r**(1 - a)``, which for 0 < a < 1 is
an increasing function of ``r``: it keeps the order of distances, so far points stay far and
the hull of the "inverted" points is (close to) the ordinary *outer* convex hull, not the
inner shape the paper describes ("the points that were originally closest to the centre are
now the furthest away").  The intended map is exponential inversion (Katz & Tal 2015 with
gamma = -a): ``P_inv = r**-a * P_i / r_i``, i.e. ``|P_inv| = r**-a`` along the same ray, which
reverses the order of distances for every a > 0.  ``method="exponential"`` implements that;
``method="literal"`` keeps the printed formula only as a diagnostic, to report what it gives.

Role of ``a``: the inverted points lie near a sphere, with radial relief ``-a * ln r``; the
smaller ``a``, the flatter the relief, the more points reach the hull and the tighter the
shape follows concavities and corners (``a -> 0`` keeps every point; large ``a`` is coarse).
For points densely covering a square's boundary the dense-sample limit cuts each corner
between (1, t*) and (t*, 1) (half-width 1, centre at the centre) where
``a t*^2 + (1 + a) t* - 1 = 0``; the relative area error is ``(1 - t*)^2 / 2`` (3.3 % at
a = 0.2, 0.4 % at a = 0.05).  With exponential inversion any a > 0 reverses the order of
distances; a = 1 is classical inversion (r -> 1/r) and a >= 1 is allowed but coarse.  With the
literal formula a = 1 puts every point on the unit sphere and a > 1 behaves like exponential
inversion with a - 1.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError, cKDTree
from shapely.geometry import Polygon

from explore3d.core.defaults import DEFAULT_A, MAX_A
from explore3d.core.interrupt import import_optional
from explore3d.core.tolerances import DEGENERACY_RTOL, MERGE_DISTANCE_M
from explore3d.core.validate import check_points, check_positive, check_vector

__all__ = ["InverseHull", "inverse_hull", "invert_points", "merge_close_points", "METHODS", "BACKENDS"]

#: Inversion methods understood by :func:`invert_points` and :func:`inverse_hull`.
METHODS = ("exponential", "spherical", "literal")
#: Convex-hull backends understood by :func:`inverse_hull`.
BACKENDS = ("scipy", "open3d")

_OPEN3D_FIX = (
    "open3d could not be imported ({err}); install it with `pip install open3d-cpu` (or `pip install open3d`) "
    "and its system library with `apt-get install libusb-1.0-0`, or use backend='scipy'"
)


def default_radius(r_max: float, a: float) -> float:
    """Default spherical-flipping radius R (metres) for points at most ``r_max`` from the centre.

    R = r_max * (1 + a) / (2 a), chosen so that spherical flipping is as tight as exponential
    inversion with the same ``a`` at the farthest point: the log-log slope of the flipped
    distance, d ln(2R - r) / d ln r = -r / (2R - r), equals exponential inversion's -a at
    r = r_max (and is flatter, i.e. tighter, closer in).  Small a gives a large R (tight), as
    with exponential inversion.  Needs 0 < a < 1 so that R > r_max (Katz et al. 2007 require
    the flipping sphere to contain every point).
    """
    if not 0 < a < 1:
        raise ValueError(
            f"spherical flipping with radius=None needs 0 < a < 1 (default R = r_max (1 + a) / (2 a) must exceed "
            f"r_max); got a={a}; pass a in (0, 1) or an explicit radius > {r_max}"
        )
    return r_max * (1.0 + a) / (2.0 * a)


def merge_close_points(points, distance: float = MERGE_DISTANCE_M) -> np.ndarray:
    """(n,) int: for each of ``points`` (n, d), metres, the index of the point that represents it
    once points closer than ``distance`` metres are merged (transitively: a cluster of chained
    near neighbours is one point); the representative is the cluster's lowest index, so
    ``np.unique(result)`` are the kept points.  Points of different clusters are farther apart
    than ``distance``.  ``distance`` = 0 merges nothing.
    """
    pts = check_points(points, "points")
    d = float(distance)
    if not (np.isfinite(d) and d >= 0):
        raise ValueError(f"merge distance must be a finite number of metres >= 0; got {distance!r}")
    n = len(pts)
    rep = np.arange(n)
    if d == 0 or n < 2:
        return rep

    pairs = cKDTree(pts).query_pairs(d, output_type="ndarray")
    if len(pairs) == 0:
        return rep
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    first = np.full(label.max() + 1, n)
    np.minimum.at(first, label, rep)
    return first[label]


def check_a(a) -> float:
    """``a`` as a float if 0 < a <= :data:`~explore3d.core.defaults.MAX_A`, else ValueError naming the range."""
    a = check_positive(a, "a")
    if a > MAX_A:
        raise ValueError(f"a must be at most {MAX_A:g} (the inverse hull's coarseness); got {a!r} (the paper uses "
                         f"0.05-0.5, the default is {DEFAULT_A})")
    return a


def check_method(method) -> str:
    """``method`` if it is one of :data:`METHODS` (the inversion kernels), else a ValueError naming them."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}; got {method!r}")
    return method


def invert_points(points, centre, a: float = DEFAULT_A, method: str = "exponential", radius=None) -> np.ndarray:
    """Invert distances from ``centre`` along each point's own ray.

    Args:
        points: (n, d) float, metres, any frame; d = 2 or 3.  No point may coincide with ``centre``.
        centre: (d,) float, metres, same frame.
        a: coarseness, > 0.  ``exponential``: |P_inv| = r**-a; ``literal``: |P_inv| = r**(1 - a)
            (the paper's formula as printed; wrong for 0 < a < 1, see the module docstring);
            ``spherical``: |P_inv| = 2R - r with R = ``radius`` or :func:`default_radius`.
        method: "exponential" | "spherical" | "literal".
        radius: spherical-flipping radius R in metres (> max distance); ignored by other methods.

    Returns:
        (n, d) float64 inverted points **relative to centre** (centre at the origin).  Units are
        metres**-a (exponential), metres**(1-a) (literal), metres (spherical).
    """
    pts = check_points(points, "points")
    c = check_vector(centre, "centre", pts.shape[1])
    a = check_a(a)
    method = check_method(method)
    rel = pts - c
    r = np.linalg.norm(rel, axis=1)
    scale = np.max(np.ptp(pts, axis=0)) if len(pts) > 1 else 0.0
    zero = r <= DEGENERACY_RTOL * max(scale, np.max(r))
    if zero.any():
        i = int(np.argmax(zero))
        raise ValueError(
            f"point {i} {pts[i].tolist()} coincides with the centre {c.tolist()} (r = {r[i]:.3g} m); "
            "remove it or choose another centre"
        )
    with np.errstate(all="raise"):
        if method == "exponential":
            new_r = r ** (-a)
        elif method == "literal":
            new_r = r ** (1.0 - a)
        else:
            rmax = float(np.max(r))
            R = default_radius(rmax, a) if radius is None else check_positive(radius, "radius")
            if R <= rmax:
                raise ValueError(
                    f"spherical flipping radius R={R} m must exceed the largest distance from the centre, {rmax} m; "
                    "pass a larger radius (or radius=None for the default)"
                )
            new_r = 2.0 * R - r
        return rel * (new_r / r)[:, None]


@dataclass(frozen=True)
class InverseHull:
    """Result of :func:`inverse_hull`.

    Attributes:
        points: (n, d) float64 input points, input frame, metres; d = 2 or 3.
        centre: (d,) float64 centre used for the inversion, same frame.
        a: coarseness parameter used.
        method: "exponential" | "spherical" | "literal".
        vertices: (k,) int indices into ``points``; 2D: ordered counter-clockwise around the
            polygon; 3D: sorted, unique.  Only one point of each cluster of points closer than
            the merge distance is ever a vertex (:func:`merge_close_points`).
        faces: 3D: (m, 3) int indices into ``points``, wound counter-clockwise seen from
            outside (outward normals); 2D: None.
    """

    points: np.ndarray
    centre: np.ndarray
    a: float
    method: str
    vertices: np.ndarray
    faces: np.ndarray | None = field(default=None)

    @property
    def dim(self) -> int:
        """2 or 3."""
        return int(self.points.shape[1])

    @property
    def polygon(self):
        """shapely Polygon of the 2D shape (input frame, metres), counter-clockwise exterior."""
        if self.dim != 2:
            raise ValueError(f"polygon is only defined for 2D inverse hulls; this one is {self.dim}D (use .mesh)")

        return Polygon(self.points[self.vertices])

    @property
    def mesh(self):
        """trimesh.Trimesh of the 3D shape (input frame, metres): watertight, outward normals,
        positive volume; only the used points are kept as vertices."""
        if self.dim != 3:
            raise ValueError(f"mesh is only defined for 3D inverse hulls; this one is {self.dim}D (use .polygon)")

        remap = np.full(len(self.points), -1, dtype=np.int64)
        remap[self.vertices] = np.arange(len(self.vertices))
        return trimesh.Trimesh(vertices=self.points[self.vertices], faces=remap[self.faces], process=False)

    def shape(self):
        """The Polygon (2D) or Trimesh (3D)."""
        return self.polygon if self.dim == 2 else self.mesh


def resolve_centre(pts: np.ndarray, centre) -> np.ndarray:
    """The (d,) centre, metres: ``centre`` given as None/"mean", "midrange" or a (d,) point, for ``pts`` (n, d)."""
    if centre is None or (isinstance(centre, str) and centre == "mean"):
        return pts.mean(axis=0)
    if isinstance(centre, str):
        if centre == "midrange":
            return 0.5 * (pts.min(axis=0) + pts.max(axis=0))
        raise ValueError(f"centre must be None, 'mean', 'midrange' or a ({pts.shape[1]},) point; got {centre!r}")
    return check_vector(centre, "centre", pts.shape[1])


def _check_not_degenerate(pts: np.ndarray) -> float:
    """Raise if the points are collinear (2D) / coplanar (3D); return the bounding-box diagonal (m)."""
    d = pts.shape[1]
    diag = float(np.linalg.norm(np.ptp(pts, axis=0)))
    rel = pts - pts.mean(axis=0)
    # Max distance from the best-fit line (2D) / plane (3D), against the bounding-box diagonal.
    _, _, vt = np.linalg.svd(rel, full_matrices=False)
    spread = float(np.max(np.abs(rel @ vt[-1])))
    if diag == 0.0 or spread <= DEGENERACY_RTOL * diag:
        what = "collinear" if d == 2 else "coplanar"
        raise ValueError(
            f"all {len(pts)} points are {what} (max off-{'line' if d == 2 else 'plane'} distance {spread:.3g} m, "
            f"bounding-box diagonal {diag:.3g} m); a {d}D shape needs points spanning {d} dimensions"
        )
    return diag


def _qhull(pts: np.ndarray, what: str) -> ConvexHull:
    try:
        return ConvexHull(pts)
    except QhullError as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValueError(f"Qhull failed on the {what} ({len(pts)} points, {pts.shape[1]}D): {first}") from None


def _check_centre_inside(pts: np.ndarray, c: np.ndarray, diag: float) -> None:
    hull = _qhull(pts, "input points")
    # equations: outward unit normals n and offsets b with n.x + b <= 0 inside.
    dist = hull.equations[:, :-1] @ c + hull.equations[:, -1]
    worst = float(dist.max())
    if worst >= -DEGENERACY_RTOL * diag:
        where = "outside" if worst > DEGENERACY_RTOL * diag else "on the boundary of"
        raise ValueError(
            f"centre {c.tolist()} is {where} the convex hull of the points (signed distance {worst:.3g} m); "
            "the centre must be strictly inside the object: use centre='mean' or 'midrange' or move it inward"
        )


def _import_open3d():
    try:
        open3d = import_optional("open3d")  # optional, heavy, needs system libusb; Ctrl-C: KeyboardInterrupt
    except (ImportError, OSError) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ImportError(_OPEN3D_FIX.format(err=msg)) from None
    return open3d


def _hull_open3d(pts: np.ndarray, c: np.ndarray, inv: np.ndarray, method: str, radius: float | None):
    """Return (vertex indices, triangles as point indices) of the inverse hull via open3d."""
    o3d = _import_open3d()
    n = len(pts)
    if method == "spherical":
        # open3d's hidden_point_removal flips |p - c| -> 2R - |p - c| itself and adds the camera
        # point (the centre) to the hull input; ``radius`` is the R invert_points used.
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
        mesh, pt_map = cloud.hidden_point_removal(c, float(radius))
    else:
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(inv))
        mesh, pt_map = cloud.compute_convex_hull(joggle_inputs=False)
    pt_map = np.asarray(pt_map, dtype=np.int64)
    tri = pt_map[np.asarray(mesh.triangles, dtype=np.int64)]
    # Strip the camera point (index n) if it was kept; with the centre strictly inside it never is.
    tri = tri[(tri < n).all(axis=1)]
    verts = np.unique(pt_map[pt_map < n])
    return verts, tri


def _orient_outward(inv: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Wind each triangle so its normal points away from the origin (the centre).

    ``inv`` is relative to the centre.  A triangle (i, j, k) of the inverted hull is outward iff
    det(inv_i, inv_j, inv_k) > 0 (its plane does not pass through the interior origin).  Since
    the inversion only rescales each point along its own ray by a positive factor, the mapped
    triangle of original points spans the same cone from the centre and has the same sign of
    that determinant: one test orients both.
    """
    det = np.einsum("ij,ij->i", inv[tri[:, 0]], np.cross(inv[tri[:, 1]], inv[tri[:, 2]]))
    out = tri.copy()
    flip = det < 0
    out[flip] = out[flip][:, [0, 2, 1]]
    return out


def inverse_hull(
    points, centre=None, a: float = DEFAULT_A, method: str = "exponential", backend: str = "scipy", radius=None,
    merge_distance: float = MERGE_DISTANCE_M,
) -> InverseHull:
    """Inverse convex hull of contact points (paper section II).

    Args:
        points: (n, d) float, metres, any frame; d = 2 (n >= 3) or 3 (n >= 4); finite, not all
            collinear (2D) / coplanar (3D).
        centre: None or "mean" (mean of the points), "midrange" (mid-point of the per-axis
            min/max extremes) -- both from the paper -- or an explicit (d,) point in metres,
            same frame.  Must lie strictly inside the convex hull of the points.
        a: coarseness > 0 (default :data:`~explore3d.core.defaults.DEFAULT_A`, 0.05; the paper: 0.2; smaller is
            tighter).  See the module docstring.
        method: "exponential" (the paper's intent, |P_inv| = r**-a), "spherical" (Katz, Tal,
            Basri 2007 spherical flipping, |P_inv| = 2R - r) or "literal" (the paper's formula
            as printed, |P_inv| = r**(1 - a): wrong, returns roughly the outer hull; diagnostic only).
        backend: "scipy" (Qhull via scipy.spatial.ConvexHull) or "open3d" (3D only; optional
            dependency, imported lazily).  With method="spherical" open3d's own
            ``hidden_point_removal(camera_location=centre, radius=R)`` does the flipping; with the
            other methods the points are inverted here and hulled by open3d's
            ``compute_convex_hull``.  Both backends give the same vertex set.
        radius: spherical-flipping radius R in metres (> the largest distance from the centre);
            None picks :func:`default_radius` from ``a``.
        merge_distance: points closer than this many metres are merged first (one of them, the
            lowest index, stands for the cluster: :func:`merge_close_points`); default
            :data:`~explore3d.core.tolerances.MERGE_DISTANCE_M` (1 um).  Near-coincident points would
            otherwise give sliver triangles that exported files and their loaders collapse
            into degenerate faces and non-manifold edges.  0 merges nothing.

    Returns:
        :class:`InverseHull`, indexing the input points.

    Raises:
        ValueError: bad input (too few / non-finite / degenerate points, centre not strictly
            inside, a <= 0, unknown method or backend, a point at the centre, Qhull failure).
        ImportError: backend="open3d" and open3d cannot be imported (message names the fix).
    """
    all_pts = check_points(points, "points")
    d = all_pts.shape[1]
    need = d + 1
    if len(all_pts) < need:
        raise ValueError(f"points needs at least {need} points in {d}D for a {d}D hull; got {len(all_pts)}")
    a = check_a(a)
    method = check_method(method)
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}; got {backend!r}")
    if backend == "open3d" and d != 3:
        raise ValueError("backend='open3d' handles 3D points only; use backend='scipy' for 2D")
    c = resolve_centre(all_pts, centre)
    kept = np.unique(merge_close_points(all_pts, merge_distance))  # indices into all_pts
    pts = all_pts[kept]
    if len(pts) < need:
        raise ValueError(f"points needs at least {need} points in {d}D for a {d}D hull; got {len(pts)} once "
                         f"points closer than {merge_distance:g} m are merged ({len(all_pts)} given)")
    diag = _check_not_degenerate(pts)
    _check_centre_inside(pts, c, diag)
    if method == "spherical" and radius is None:
        radius = default_radius(float(np.max(np.linalg.norm(pts - c, axis=1))), a)
    inv = invert_points(pts, c, a=a, method=method, radius=radius)

    with np.errstate(all="raise"):
        if d == 2:
            hull = _qhull(inv, f"{method}-inverted points")
            verts = np.asarray(hull.vertices, dtype=np.int64)  # counter-clockwise for 2D in Qhull/scipy
            ring = pts[verts]
            x, y = ring[:, 0], ring[:, 1]
            signed_area = 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
            if signed_area < 0:
                verts = verts[::-1]
            return InverseHull(all_pts, c, a, method, kept[verts], None)

        if backend == "scipy":
            hull = _qhull(inv, f"{method}-inverted points")
            tri = np.asarray(hull.simplices, dtype=np.int64)
            verts = np.unique(np.asarray(hull.vertices, dtype=np.int64))
        else:
            verts, tri = _hull_open3d(pts, c, inv, method, radius)
        faces = _orient_outward(inv, tri)
    return InverseHull(all_pts, c, a, method, kept[verts], kept[faces])
