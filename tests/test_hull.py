"""Tests of explore3d.geometry.hull: known answers, convergence in a, rigid-motion invariance, the
literal formula's outer hull, star-shapedness, backend agreement and input validation."""
from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest
import trimesh
from scipy.spatial import ConvexHull, QhullError
from scipy.spatial.transform import Rotation

import explore3d.geometry.hull as hull_mod
from explore3d.geometry.hull import InverseHull, default_radius, inverse_hull, invert_points
from explore3d.core.tolerances import FLOAT64_GEOMETRY_RTOL, INVERSE_HULL_VOLUME_RTOL

CUBE_SIDE_M = 0.08
SPHERE_RADIUS_M = 0.05


def cube_samples(n: int = 4000, seed: int = 1) -> tuple[np.ndarray, trimesh.Trimesh]:
    """(n, 3) seeded random points on an 80 mm cube centred at the origin, and the cube."""
    cube = trimesh.creation.box((CUBE_SIDE_M,) * 3)
    pts, _ = trimesh.sample.sample_surface(cube, n, seed=np.random.default_rng(seed))
    return np.asarray(pts, dtype=np.float64), cube


def sphere_samples(n: int = 4000, seed: int = 2) -> np.ndarray:
    """(n, 3) seeded points uniformly on a 50 mm sphere centred at the origin (exactly on it)."""
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return SPHERE_RADIUS_M * v / np.linalg.norm(v, axis=1, keepdims=True)


def square_boundary(half_width: float, per_edge: int) -> np.ndarray:
    """(4 (per_edge - 1), 2) points evenly on the boundary of a square centred at the origin."""
    t = np.linspace(-half_width, half_width, per_edge)[:-1]
    w = np.full_like(t, half_width)
    return np.concatenate(
        [np.c_[w, t], np.c_[-t, w], np.c_[-w, -t], np.c_[t, -w]]  # each edge counter-clockwise
    )


def star_boundary(n_tips: int = 5, r_out: float = 0.05, r_in: float = 0.02, per_edge: int = 50) -> np.ndarray:
    """(2 n_tips per_edge, 2) points along the edges of a concave star polygon centred at the origin."""
    ang = np.arange(2 * n_tips) * np.pi / n_tips
    rad = np.where(np.arange(2 * n_tips) % 2 == 0, r_out, r_in)
    corners = np.c_[rad * np.cos(ang), rad * np.sin(ang)]
    s = np.linspace(0.0, 1.0, per_edge, endpoint=False)[:, None]
    return np.concatenate([corners[i] + s * (corners[(i + 1) % len(corners)] - corners[i]) for i in range(len(corners))])


def random_rigid(rng: np.random.Generator, d: int) -> tuple[np.ndarray, np.ndarray]:
    """A seeded proper rotation (d, d) and a translation (d,) of up to 1 m."""
    if d == 2:
        th = rng.uniform(0, 2 * np.pi)
        R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    else:
        R = Rotation.random(random_state=rng).as_matrix()
    return R, rng.uniform(-1.0, 1.0, d)


def corner_cut_t(a: float) -> float:
    """Dense-limit corner cut of a unit half-width square: the tangent point t* of the inverted edge.

    Edge x = 1 inverts to q(t) = (1 + t^2)^(-(1 + a)/2) (1, t); the hull bridges the corner with
    the support line normal to the diagonal, touching where d/dt [q(t) . (1, 1)] = 0, i.e.
    a t^2 + (1 + a) t - 1 = 0.
    """
    return (-(1 + a) + np.sqrt((1 + a) ** 2 + 4 * a)) / (2 * a)


def volume_rel_error(h: InverseHull, true_volume: float) -> float:
    return abs(h.mesh.volume - true_volume) / true_volume


# ---------------------------------------------------------------- invert_points (pure map)


def test_invert_points_maps_along_rays_with_stated_lengths():
    rng = np.random.default_rng(0)
    c = np.array([0.1, -0.2, 0.3])
    p = c + rng.normal(size=(50, 3)) * 0.05
    rel = p - c
    r = np.linalg.norm(rel, axis=1)
    a = 0.2
    R = 1.5 * r.max()
    cases = {
        "exponential": r ** -a,
        "literal": r ** (1 - a),
        "spherical": 2 * R - r,
    }
    for method, expect in cases.items():
        q = invert_points(p, c, a=a, method=method, radius=R)
        np.testing.assert_allclose(np.linalg.norm(q, axis=1), expect, rtol=1e-12)
        # Same ray: unit directions unchanged.
        np.testing.assert_allclose(q / np.linalg.norm(q, axis=1)[:, None], rel / r[:, None], atol=1e-12)
    # Exponential and spherical reverse the order of distances, the literal formula keeps it.
    order = np.argsort(r)
    for method in ("exponential", "spherical"):
        assert np.all(np.diff(np.linalg.norm(invert_points(p, c, a, method, R), axis=1)[order]) < 0)
    assert np.all(np.diff(np.linalg.norm(invert_points(p, c, a, "literal"), axis=1)[order]) > 0)


def test_default_radius_matches_exponential_slope_at_farthest_point():
    r_max, a = 0.07, 0.2
    R = default_radius(r_max, a)
    # d ln(2R - r) / d ln r at r_max equals -a.
    assert -r_max / (2 * R - r_max) == pytest.approx(-a, rel=1e-12)
    assert R > r_max


# ---------------------------------------------------------------- 2D known answer


@pytest.mark.parametrize("a", [0.2, 0.05])
def test_square_area_matches_dense_limit_corner_cut(a):
    w, per_edge = 0.04, 2001
    h_m = 2 * w / (per_edge - 1)  # sample spacing
    pts = square_boundary(w, per_edge)
    ih = inverse_hull(pts, centre=np.zeros(2), a=a)
    poly = ih.polygon
    assert poly.is_valid and poly.exterior.is_ccw
    cut_leg = w * (1 - corner_cut_t(a))
    expected = 4 * w**2 - 4 * 0.5 * cut_leg**2
    # The chosen corner vertices lie within one spacing of the dense-limit tangent points, so
    # each of 4 corner triangles (legs cut_leg +- h) changes by at most cut_leg h + h^2 / 2.
    tol = 4 * (cut_leg * h_m + 0.5 * h_m**2)
    assert abs(poly.area - expected) <= tol
    # The relative error is (1 - t*)^2 / 2: e.g. 3.3 % at a = 0.2.
    assert (4 * w**2 - poly.area) / (4 * w**2) == pytest.approx((1 - corner_cut_t(a)) ** 2 / 2, abs=tol / (4 * w**2))


def test_2d_polygon_is_star_shaped_ccw_and_valid():
    rng = np.random.default_rng(3)
    pts = star_boundary() + rng.normal(scale=1e-3, size=(500, 2))
    ih = inverse_hull(pts, a=0.2)
    ring = ih.points[ih.vertices] - ih.centre
    ang = np.unwrap(np.arctan2(ring[:, 1], ring[:, 0]))
    steps = np.diff(np.r_[ang, ang[0] + 2 * np.pi])
    assert np.all(steps > 0)  # strictly counter-clockwise about the centre, once around
    assert ang[-1] - ang[0] < 2 * np.pi
    poly = ih.polygon
    assert poly.is_valid and poly.exterior.is_ccw
    from shapely.geometry import Point

    assert poly.contains(Point(ih.centre))


# ---------------------------------------------------------------- 3D known answers and convergence


def test_cube_mesh_is_closed_outward_and_within_target():
    pts, cube = cube_samples()
    ih = inverse_hull(pts, a=0.05)
    m = ih.mesh
    assert m.is_watertight and m.is_winding_consistent
    assert m.volume > 0
    assert volume_rel_error(ih, cube.volume) < INVERSE_HULL_VOLUME_RTOL
    # faces index the original points; the mesh keeps only those used.
    assert set(np.unique(ih.faces)) == set(ih.vertices.tolist())
    np.testing.assert_array_equal(m.vertices, pts[ih.vertices])


def test_sphere_mesh_is_closed_outward_and_within_target():
    pts = sphere_samples()
    true_volume = 4.0 / 3.0 * np.pi * SPHERE_RADIUS_M**3
    ih = inverse_hull(pts, a=0.2)
    m = ih.mesh
    assert m.is_watertight and m.is_winding_consistent and m.volume > 0
    assert volume_rel_error(ih, true_volume) < INVERSE_HULL_VOLUME_RTOL
    # All points are equidistant from the true centre, so every one is a hull vertex there.
    assert len(inverse_hull(pts, centre=np.zeros(3), a=0.2).vertices) == len(pts)


def test_cube_error_falls_as_a_falls():
    pts, cube = cube_samples()
    errors = [volume_rel_error(inverse_hull(pts, a=a), cube.volume) for a in (0.5, 0.2, 0.05)]
    assert errors[0] > errors[1] > errors[2]


def test_3d_surface_is_star_shaped_about_centre():
    pts, _ = cube_samples(2000)
    ih = inverse_hull(pts, a=0.2)
    tri = ih.points[ih.faces] - ih.centre  # (m, 3, 3)
    a_, b_, c_ = tri[:, 0], tri[:, 1], tri[:, 2]
    det = np.einsum("ij,ij->i", a_, np.cross(b_, c_))
    assert np.all(det > 0)  # every face wound counter-clockwise seen from outside the centre
    # Solid angles (Van Oosterom & Strackee) sum to 4 pi: every ray from the centre crosses once.
    la, lb, lc = (np.linalg.norm(v, axis=1) for v in (a_, b_, c_))
    denom = la * lb * lc + np.einsum("ij,ij->i", a_, b_) * lc + np.einsum("ij,ij->i", a_, c_) * lb
    denom += np.einsum("ij,ij->i", b_, c_) * la
    omega = 2 * np.arctan2(det, denom)
    assert omega.sum() == pytest.approx(4 * np.pi, rel=1e-9)


# ---------------------------------------------------------------- invariance


@pytest.mark.parametrize("d", [2, 3])
def test_rigid_motion_keeps_vertex_set(d):
    rng = np.random.default_rng(10 + d)
    pts = star_boundary() + rng.normal(scale=1e-3, size=(500, 2)) if d == 2 else cube_samples(1500)[0]
    centre = pts.mean(axis=0) + 0.003
    ref = inverse_hull(pts, centre=centre, a=0.2)
    for _ in range(3):
        R, t = random_rigid(rng, d)
        moved = inverse_hull(pts @ R.T + t, centre=R @ centre + t, a=0.2)
        np.testing.assert_array_equal(np.sort(moved.vertices), np.sort(ref.vertices))
        if d == 3:
            assert {tuple(sorted(f)) for f in moved.faces} == {tuple(sorted(f)) for f in ref.faces}
            assert moved.mesh.volume == pytest.approx(ref.mesh.volume, rel=FLOAT64_GEOMETRY_RTOL)


# ---------------------------------------------------------------- the literal formula


def test_literal_formula_gives_outer_hull_2d():
    pts = star_boundary()
    lit = inverse_hull(pts, centre=np.zeros(2), a=0.2, method="literal")
    outer = ConvexHull(pts).vertices
    assert set(lit.vertices.tolist()) == set(outer.tolist())  # the 5 tips
    # Whereas the intended exponential inversion keeps the concave inner corners.
    expo = inverse_hull(pts, centre=np.zeros(2), a=0.2)
    inner_corners = np.flatnonzero(np.isclose(np.linalg.norm(pts, axis=1), 0.02))
    assert set(inner_corners.tolist()) <= set(expo.vertices.tolist())
    assert not set(inner_corners.tolist()) & set(lit.vertices.tolist())


def test_literal_formula_gives_outer_hull_3d():
    rng = np.random.default_rng(5)
    shell = sphere_samples(600, seed=6)
    inside = rng.normal(size=(400, 3))
    inside *= (rng.uniform(0.2, 0.5, 400) * SPHERE_RADIUS_M / np.linalg.norm(inside, axis=1))[:, None]
    pts = np.concatenate([shell, inside])
    lit = inverse_hull(pts, centre=np.zeros(3), a=0.2, method="literal")
    np.testing.assert_array_equal(lit.vertices, np.sort(ConvexHull(pts).vertices))
    # Exponential picks the innermost points instead.
    assert set(inverse_hull(pts, centre=np.zeros(3), a=0.2).vertices.tolist()) <= set(range(600, 1000))


# ---------------------------------------------------------------- backends


@pytest.mark.needs_open3d
@pytest.mark.parametrize("method", ["spherical", "exponential"])
def test_open3d_and_scipy_pick_same_vertices(method):
    pts, _ = cube_samples(3000, seed=7)
    sp = inverse_hull(pts, a=0.2, method=method, backend="scipy")
    o3 = inverse_hull(pts, a=0.2, method=method, backend="open3d")
    np.testing.assert_array_equal(o3.vertices, sp.vertices)
    assert o3.mesh.is_watertight and o3.mesh.is_winding_consistent
    assert o3.mesh.volume == pytest.approx(sp.mesh.volume, rel=FLOAT64_GEOMETRY_RTOL)


def test_import_without_open3d_and_backend_error_names_fix():
    code = textwrap.dedent(
        """
        import sys
        sys.modules["open3d"] = None  # any `import open3d` now raises ImportError
        import numpy as np
        import explore3d.geometry.hull as h
        pts = np.random.default_rng(0).normal(size=(50, 3))
        assert len(h.inverse_hull(pts).vertices) > 0
        try:
            h.inverse_hull(pts, backend="open3d", method="spherical")
        except ImportError as exc:
            print(exc)
        else:
            raise SystemExit("no ImportError")
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    msg = out.stdout.strip()
    assert len(msg.splitlines()) == 1
    assert "open3d-cpu" in msg and "libusb-1.0-0" in msg


# ---------------------------------------------------------------- validation


_SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
_TETRA = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(points=_SQUARE[:2]), "at least 3"),
        (dict(points=_TETRA[:3]), "at least 4"),
        (dict(points=np.ones((5, 4))), "shape"),
        (dict(points=np.r_[_SQUARE, [[np.nan, 0.5]]]), "finite"),
        (dict(points=np.r_[_TETRA, [[np.inf, 0, 0]]]), "finite"),
        (dict(points=np.c_[np.arange(5.0), 2 * np.arange(5.0)]), "collinear"),
        (dict(points=np.c_[np.random.default_rng(0).random((20, 2)), np.zeros(20)]), "coplanar"),
        (dict(points=_SQUARE, centre=[2.0, 0.5]), "outside"),
        (dict(points=_SQUARE, centre=[1.0, 0.5]), "boundary"),
        (dict(points=_SQUARE, centre=[0.0, 0.0]), "boundary"),
        (dict(points=_SQUARE, centre="middle"), "centre must be"),
        (dict(points=_SQUARE, centre=[0.5, 0.5, 0.5]), "centre"),
        (dict(points=_SQUARE, a=0.0), "a must be"),
        (dict(points=_SQUARE, a=-0.2), "a must be"),
        (dict(points=_SQUARE, a=np.nan), "a must be"),
        (dict(points=_SQUARE, method="inverse"), "method must be"),
        (dict(points=_SQUARE, backend="cgal"), "backend must be"),
        (dict(points=_SQUARE, backend="open3d"), "3D points only"),
        (dict(points=np.r_[_SQUARE, [[0.5, 0.5]]]), "coincides with the centre"),
        (dict(points=_SQUARE, method="spherical", radius=0.5), "must exceed"),
        (dict(points=_SQUARE, method="spherical", a=1.5), "0 < a < 1"),
    ],
)
def test_bad_input_raises_value_error(kwargs, match):
    with pytest.raises(ValueError, match=match):
        inverse_hull(**kwargs)


def test_qhull_error_is_wrapped(monkeypatch):
    def broken(*args, **kwargs):
        raise QhullError("QH6154 Qhull precision error: initial simplex is flat")

    monkeypatch.setattr(hull_mod, "ConvexHull", broken)
    with pytest.raises(ValueError, match="Qhull failed.*QH6154") as info:
        inverse_hull(_TETRA)
    assert not isinstance(info.value, QhullError)


def test_shape_accessors_check_dimension():
    ih2 = inverse_hull(_SQUARE)
    ih3 = inverse_hull(_TETRA)
    assert ih2.dim == 2 and ih3.dim == 3
    with pytest.raises(ValueError, match="2D"):
        ih3.polygon
    with pytest.raises(ValueError, match="3D"):
        ih2.mesh
    assert ih2.shape().area == pytest.approx(1.0)
    assert ih3.shape().volume == pytest.approx(1.0 / 6.0)
    assert ih2.faces is None


def test_named_centres():
    pts = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 2.0], [0.0, 2.0], [1.0, 1.0]])
    np.testing.assert_allclose(inverse_hull(pts, centre="midrange").centre, [2.0, 1.0])
    np.testing.assert_allclose(inverse_hull(pts, centre="mean").centre, [1.8, 1.0])
    np.testing.assert_allclose(inverse_hull(pts).centre, [1.8, 1.0])
