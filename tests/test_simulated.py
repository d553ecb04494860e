"""Tests for explore3d.world.simulated: link placement facts and the paper's simulated-cube result."""
from __future__ import annotations

import numpy as np
import pytest
import shapely
import trimesh
from shapely.geometry import MultiPolygon

from explore3d.world import objects
from explore3d.world.simulated import discretise_links, random_links_on_boundary, simulated_case
from explore3d.core.tolerances import SURFACE_ATOL_M

L = 0.008  # the paper's simulated link length, metres
SEEDS = range(10)

POLYGONS = {
    "square": objects.square(0.08),
    "100-gon": objects.regular_polygon(0.063, 100),
    "l_profile": objects.l_profile(),
    "star": objects.star_polygon(),
    "u_profile": objects.u_profile(),
}


def link_lengths(seg):
    return np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)


# ------------------------------------------------------------------------------------------
# 2D link placement
# ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(POLYGONS))
def test_2d_links_touch_and_stay_outside(name):
    poly = POLYGONS[name]
    seg = random_links_on_boundary(poly, 400, L, np.random.default_rng(1))
    assert seg.shape == (400, 2, 2)
    assert np.allclose(link_lengths(seg), L, rtol=1e-12)
    lines = shapely.linestrings(seg)
    # touching: every link meets the boundary
    assert np.all(shapely.distance(lines, poly.exterior) <= SURFACE_ATOL_M)
    # outside: no link enters the interior (the polygon shrunk by the tolerance)
    assert not shapely.intersects(lines, poly.buffer(-SURFACE_ATOL_M)).any()
    # tangent: each link lies on the supporting line of a boundary edge that it touches
    ring = np.asarray(poly.exterior.coords)
    a, b = ring[:-1], ring[1:]
    u = (b - a) / np.linalg.norm(b - a, axis=1)[:, None]
    edges = shapely.linestrings(np.stack([a, b], axis=1))
    for i in range(0, 400, 7):
        off = sum(np.abs(u[:, 0] * (p - a)[:, 1] - u[:, 1] * (p - a)[:, 0]) for p in seg[i])
        touch = shapely.distance(edges, lines[i]) <= SURFACE_ATOL_M
        assert (touch & (off <= 1e-12)).any(), i


def test_2d_convex_links_are_uniform_by_arc_length():
    # on the square the touching points are uniform along the perimeter: each side gets ~1/4
    poly = POLYGONS["square"]
    seg = random_links_on_boundary(poly, 4000, L, np.random.default_rng(7))
    d = seg[:, 1] - seg[:, 0]
    horizontal = np.abs(d[:, 1]) < 1e-15
    side_y = np.where(horizontal, np.sign(seg[:, 0, 1]), 0)
    side_x = np.where(~horizontal, np.sign(seg[:, 0, 0]), 0)
    counts = [np.sum(side_y > 0), np.sum(side_y < 0), np.sum(side_x > 0), np.sum(side_x < 0)]
    # binomial(4000, 1/4): sd ~ 27; 5 sd
    assert all(abs(c - 1000) < 137 for c in counts), counts


def test_concave_notch_narrower_than_link_gets_no_links():
    # a slot 4 mm wide and 30 mm deep: an 8 mm link touching the slot floor cannot lie flat there
    slot = shapely.Polygon([(-0.04, -0.04), (0.04, -0.04), (0.04, 0.04), (0.002, 0.04), (0.002, 0.01),
                            (-0.002, 0.01), (-0.002, 0.04), (-0.04, 0.04)])
    seg = random_links_on_boundary(slot, 500, L, np.random.default_rng(3))
    floor = shapely.LineString([(-0.002, 0.01), (0.002, 0.01)])
    assert not (shapely.distance(shapely.linestrings(seg), floor) <= SURFACE_ATOL_M).any()
    assert not shapely.intersects(shapely.linestrings(seg), slot.buffer(-SURFACE_ATOL_M)).any()


# ------------------------------------------------------------------------------------------
# 3D link placement
# ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["cube", "sphere", "cylinder"])
def test_3d_convex_links_touch_and_stay_outside(name):
    mesh = objects.BUILTIN_OBJECTS[name].builder()
    seg = random_links_on_boundary(mesh, 150, L, np.random.default_rng(2))
    assert seg.shape == (150, 2, 3)
    assert np.allclose(link_lengths(seg), L, rtol=1e-12)
    # no point strictly inside: for a convex mesh, inside means below every face plane
    pts = discretise_links(seg, 41)
    n, p0 = mesh.face_normals, mesh.triangles[:, 0]
    height = pts @ n.T - np.einsum("ij,ij->i", n, p0)[None, :]  # (points, faces), > 0 outside
    assert np.all(height.max(axis=1) >= -SURFACE_ATOL_M)
    # touching: sampled every 40 um, each link comes within half a spacing of the surface
    # (distance to the surface is 1-Lipschitz along the link and 0 at the touching point)
    dense = discretise_links(seg[:40], 201)
    _, dist, _ = trimesh.proximity.closest_point(mesh, dense)
    assert np.all(dist.reshape(40, 201).min(axis=1) <= 0.5 * L / 200 + SURFACE_ATOL_M)
    # tangent: both ends lie on one face plane
    end_h = np.stack([seg[:, k] @ n.T - np.einsum("ij,ij->i", n, p0) for k in range(2)])
    assert np.all((np.abs(end_h).max(axis=0) <= 1e-12).any(axis=1))


def test_3d_concave_links_do_not_penetrate():
    mesh = objects.l_block()
    seg = random_links_on_boundary(mesh, 120, L, np.random.default_rng(4))
    depth = trimesh.proximity.signed_distance(mesh, discretise_links(seg, 81))  # > 0 inside
    assert depth.max() <= 1e-7  # sampled 10x finer than the sampler's own check


# ------------------------------------------------------------------------------------------
# discretisation, determinism, validation
# ------------------------------------------------------------------------------------------


def test_discretise_links_spacing_and_order():
    seg = np.array([[[0.0, 0.0], [0.008, 0.0]], [[1.0, 1.0], [1.0, 1.004]]])
    pts = discretise_links(seg, 5)
    assert pts.shape == (10, 2)
    assert np.allclose(pts[:5, 0], [0.0, 0.002, 0.004, 0.006, 0.008])
    assert np.allclose(pts[5:, 1], 1.0 + np.array([0.0, 0.001, 0.002, 0.003, 0.004]))
    with pytest.raises(ValueError, match="points_per_link"):
        discretise_links(seg, 1)
    with pytest.raises(ValueError, match="shape"):
        discretise_links(np.zeros((3, 3, 2)), 4)


def test_deterministic_for_a_seed():
    poly = POLYGONS["square"]
    a = random_links_on_boundary(poly, 50, L, np.random.default_rng(11))
    b = random_links_on_boundary(poly, 50, L, np.random.default_rng(11))
    c = random_links_on_boundary(poly, 50, L, np.random.default_rng(12))
    assert np.array_equal(a, b) and not np.allclose(a, c)
    s1, s2 = simulated_case(poly, seed=5), simulated_case(poly, seed=5)
    assert np.array_equal(s1.points, s2.points) and s1.error.percent == s2.error.percent


@pytest.mark.parametrize(
    "args, match",
    [
        ((POLYGONS["square"], 0, L), "n_links"),
        ((POLYGONS["square"], 10, -L), "link_length"),
        ((MultiPolygon([objects.square(0.01)]), 10, L), "Polygon"),
    ],
)
def test_bad_inputs(args, match):
    with pytest.raises(ValueError, match=match):
        random_links_on_boundary(*args, np.random.default_rng(0))


def test_rng_must_be_a_generator():
    with pytest.raises(ValueError, match="Generator"):
        random_links_on_boundary(POLYGONS["square"], 10, L, 0)


def test_open_mesh_rejected():
    mesh = objects.cube()
    with pytest.raises(ValueError, match="closed volume"):
        random_links_on_boundary(trimesh.Trimesh(mesh.vertices, mesh.faces[1:]), 10, L, np.random.default_rng(0))


# ------------------------------------------------------------------------------------------
# the paper's simulated cube (Fig. 10, Table I: 3.3 %)
# ------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def paper_cases():
    sq = objects.square(0.08)
    exp = [simulated_case(sq, n_links=320, link_length=L, a=0.2, seed=s) for s in SEEDS]
    lit = [simulated_case(sq, n_links=320, link_length=L, a=0.2, method="literal", seed=s) for s in SEEDS]
    return exp, lit


def test_simulated_cube_error_within_2_to_5_percent(paper_cases):
    exp, _ = paper_cases
    percent = np.array([c.error.percent for c in exp])
    assert np.all((percent >= 2.0) & (percent <= 5.0)), percent.round(2)


def test_simulated_cube_error_agrees_with_shapely(paper_cases):
    # independent check of the reported error: eq. (6)-(7) with shapely on the hull polygon
    sq = objects.square(0.08)
    for case in paper_cases[0][:3]:
        poly = case.hull.polygon
        a_err = poly.area + sq.area - 2.0 * poly.intersection(sq).area
        assert case.error.percent == pytest.approx(100.0 * a_err / sq.area, rel=1e-6)


def test_literal_formula_is_worse(paper_cases):
    exp, lit = paper_cases
    for e, l in zip(exp, lit):
        assert l.error.percent > e.error.percent


def test_3d_sphere_error_falls_with_more_links():
    # convergence: ten times the links cover the sphere far better (a = 0.2, 5 points per link)
    sph = objects.sphere(0.05, 4)
    for seed in range(3):
        few = simulated_case(sph, n_links=150, seed=seed).error.percent
        many = simulated_case(sph, n_links=1500, seed=seed).error.percent
        assert many < 0.5 * few, (seed, few, many)
