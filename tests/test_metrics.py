"""Tests of explore3d.geometry.metrics: exact areas and volumes, agreement with shapely, rigid-motion
invariance, identity, closed-volume checks and determinism."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation
from shapely import affinity
from shapely.geometry import Point, Polygon, box

from explore3d.geometry.hull import inverse_hull
from explore3d.geometry.metrics import NotAVolumeError, ShapeError, area_error, boundary_samples, check_volume, shape_error, volume_error
from explore3d.core.tolerances import FLOAT64_GEOMETRY_RTOL


def rigid_mesh(mesh: trimesh.Trimesh, R: np.ndarray, t: np.ndarray) -> trimesh.Trimesh:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return mesh.copy().apply_transform(T)


def rigid_polygon(poly: Polygon, th: float, t: np.ndarray) -> Polygon:
    c, s = np.cos(th), np.sin(th)
    return affinity.affine_transform(poly, [c, -s, s, c, t[0], t[1]])


# ---------------------------------------------------------------- known answers


def test_two_offset_unit_squares_exact():
    # Overlap of [0,1]^2 and [0.5,1.5]x[0.25,1.25] is 0.5 x 0.75 = 0.375.
    e = shape_error(box(0.5, 0.25, 1.5, 1.25), box(0, 0, 1, 1))
    assert e.dim == 2
    assert e.intersection_size == pytest.approx(0.375, rel=FLOAT64_GEOMETRY_RTOL)
    assert e.sym_diff == pytest.approx(2 - 2 * 0.375, rel=FLOAT64_GEOMETRY_RTOL)
    assert e.err == pytest.approx(1.25, rel=FLOAT64_GEOMETRY_RTOL)
    assert e.percent == pytest.approx(125.0, rel=FLOAT64_GEOMETRY_RTOL)
    assert e.iou == pytest.approx(0.375 / 1.625, rel=FLOAT64_GEOMETRY_RTOL)
    # The farthest boundary point of either square from the other's boundary: the corner
    # (1.5, 1.25) is 0.5 from x = 1 and 0.25 from y = 1 -> distance to the corner (1, 1) is
    # sqrt(0.5^2 + 0.25^2); sampled boundaries include the vertices, so this is exact.
    assert e.hausdorff_m == pytest.approx(np.hypot(0.5, 0.25), rel=1e-12)
    assert area_error(box(0.5, 0.25, 1.5, 1.25), box(0, 0, 1, 1)) == pytest.approx(1.25, rel=FLOAT64_GEOMETRY_RTOL)


def test_cube_vs_shifted_cube_exact():
    cube = trimesh.creation.box((1.0, 1.0, 1.0))
    shifted = cube.copy().apply_translation([0.3, 0.2, 0.1])
    v_int = 0.7 * 0.8 * 0.9
    e = shape_error(shifted, cube)
    assert e.dim == 3
    assert e.intersection_size == pytest.approx(v_int, rel=FLOAT64_GEOMETRY_RTOL)
    assert e.sym_diff == pytest.approx(2 - 2 * v_int, rel=FLOAT64_GEOMETRY_RTOL)
    assert e.iou == pytest.approx(v_int / (2 - v_int), rel=FLOAT64_GEOMETRY_RTOL)
    assert volume_error(shifted, cube) == pytest.approx(2 - 2 * v_int, rel=FLOAT64_GEOMETRY_RTOL)


def test_disjoint_shapes_have_zero_intersection():
    far = trimesh.creation.box((1.0, 1.0, 1.0)).apply_translation([3.0, 0, 0])
    e = shape_error(far, trimesh.creation.box((1.0, 1.0, 1.0)), n_samples=500)
    assert e.intersection_size == 0.0 and e.iou == 0.0 and e.err == pytest.approx(2.0)


def test_2d_intersection_agrees_with_shapely():
    rng = np.random.default_rng(4)
    for _ in range(5):
        truth = Point(rng.normal(size=2) * 0.01).buffer(0.05, 32)
        est = Polygon(rng.normal(size=(3, 2)) * 0.01 + [[0.06, 0], [0, 0.06], [-0.06, -0.03]])
        e = shape_error(est, truth, n_samples=2000)
        inter = est.intersection(truth).area
        assert e.intersection_size == pytest.approx(inter, rel=FLOAT64_GEOMETRY_RTOL)
        assert e.sym_diff == pytest.approx(est.symmetric_difference(truth).area, rel=1e-9, abs=1e-15)


def test_identical_shapes_give_zero_error():
    poly = Point(0.1, 0.2).buffer(0.05, 16)
    e2 = shape_error(poly, poly)
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.05)
    e3 = shape_error(mesh, mesh.copy(), n_samples=2000)
    for e in (e2, e3):
        assert e.sym_diff == pytest.approx(0.0, abs=FLOAT64_GEOMETRY_RTOL * e.true_size)
        assert e.iou == pytest.approx(1.0, rel=FLOAT64_GEOMETRY_RTOL)
        assert e.chamfer_m == 0.0 and e.hausdorff_m == 0.0


def test_accepts_inverse_hull_and_mixed_dims_fail():
    cube = trimesh.creation.box((0.08, 0.08, 0.08))
    pts, _ = trimesh.sample.sample_surface(cube, 2000, seed=np.random.default_rng(0))
    ih = inverse_hull(pts, a=0.05)
    e = shape_error(ih, cube, n_samples=2000)
    assert e.estimate_size == pytest.approx(ih.mesh.volume, rel=FLOAT64_GEOMETRY_RTOL)
    # The inverse hull's vertices lie on the cube's surface, so it lies inside the cube.
    assert e.intersection_size == pytest.approx(e.estimate_size, rel=1e-9)
    with pytest.raises(ValueError, match="2D"):
        shape_error(box(0, 0, 1, 1), cube)
    with pytest.raises(ValueError, match="shapely Polygon"):
        shape_error(np.zeros((3, 2)), box(0, 0, 1, 1))


# ---------------------------------------------------------------- invariance and determinism


def test_every_measure_is_rigid_motion_invariant_3d():
    rng = np.random.default_rng(7)
    truth = trimesh.creation.cylinder(radius=0.063, height=0.08, sections=40)
    pts, _ = trimesh.sample.sample_surface(truth, 1500, seed=np.random.default_rng(8))
    est = inverse_hull(pts, a=0.1).mesh
    ref = shape_error(est, truth, n_samples=3000, seed=3).to_dict()
    for _ in range(2):
        R, t = Rotation.random(random_state=rng).as_matrix(), rng.uniform(-1, 1, 3)
        moved = shape_error(rigid_mesh(est, R, t), rigid_mesh(truth, R, t), n_samples=3000, seed=3).to_dict()
        for k, v in ref.items():
            assert moved[k] == pytest.approx(v, rel=FLOAT64_GEOMETRY_RTOL, abs=1e-15), k


def test_every_measure_is_rigid_motion_invariant_2d():
    rng = np.random.default_rng(9)
    truth = box(-0.04, -0.04, 0.04, 0.04)
    est = Point(0.005, 0.0).buffer(0.045, 24)
    ref = shape_error(est, truth, n_samples=3000).to_dict()
    for _ in range(3):
        th, t = rng.uniform(0, 2 * np.pi), rng.uniform(-1, 1, 2)
        moved = shape_error(rigid_polygon(est, th, t), rigid_polygon(truth, th, t), n_samples=3000).to_dict()
        for k, v in ref.items():
            assert moved[k] == pytest.approx(v, rel=FLOAT64_GEOMETRY_RTOL, abs=1e-15), k


def test_deterministic_for_a_seed_and_seed_matters():
    truth = trimesh.creation.icosphere(subdivisions=2, radius=0.05)
    est = trimesh.creation.box((0.08, 0.08, 0.08))
    a = shape_error(est, truth, n_samples=1000, seed=11)
    b = shape_error(est, truth, n_samples=1000, seed=11)
    c = shape_error(est, truth, n_samples=1000, seed=12)
    assert a == b
    assert a.chamfer_m != c.chamfer_m


def test_to_dict_is_json_friendly():
    import json

    d = shape_error(box(0, 0, 1, 1), box(0.5, 0, 1.5, 1), n_samples=100).to_dict()
    assert json.loads(json.dumps(d)) == d
    assert set(d) == set(ShapeError.__dataclass_fields__)


def test_boundary_samples_lie_on_the_boundary_evenly():
    poly = box(0, 0, 2, 1)
    s = boundary_samples(poly, 600)
    assert len(s) == 600 + 4
    assert np.max([poly.exterior.distance(Point(p)) for p in s]) < 1e-12
    # 600 samples on a perimeter of 6 m: spacing 0.01 m.
    d = np.linalg.norm(np.diff(s[:600], axis=0), axis=1)
    np.testing.assert_allclose(d, 0.01, atol=1e-9)


# ---------------------------------------------------------------- closed volumes


def test_open_mesh_raises_not_a_volume():
    cube = trimesh.creation.box((1.0, 1.0, 1.0))
    open_cube = trimesh.Trimesh(cube.vertices, cube.faces[:-2], process=False)  # one square face removed
    with pytest.raises(NotAVolumeError, match="not watertight"):
        check_volume(open_cube, "truth")
    with pytest.raises(NotAVolumeError, match="truth"):
        shape_error(cube, open_cube)
    assert issubclass(NotAVolumeError, ValueError)


def test_inverted_mesh_raises_not_a_volume():
    cube = trimesh.creation.box((1.0, 1.0, 1.0))
    inside_out = cube.copy()
    inside_out.invert()
    with pytest.raises(NotAVolumeError, match="non-positive volume"):
        check_volume(inside_out, "truth")
    flipped_one = trimesh.Trimesh(cube.vertices, np.r_[cube.faces[:-1], cube.faces[-1:, ::-1]], process=False)
    with pytest.raises(NotAVolumeError, match="winding"):
        check_volume(flipped_one, "truth")
    assert check_volume(cube, "truth") is cube


@pytest.mark.parametrize("seed", range(6))
def test_a_shape_against_itself_is_exactly_zero_error_and_iou_one(seed):
    """Error >= 0 and IoU <= 1 always: before the clamp, ``shape_error(x, x)`` gave -4e-16 error and
    IoU 1 + 4e-16 in most 3D cases (the boolean's and trimesh's volume sums round differently)."""
    from explore3d.world.objects import BUILTIN_OBJECTS, load_object

    rng = np.random.default_rng(seed)
    names = sorted(BUILTIN_OBJECTS)
    for name in (names[seed % len(names)], names[(seed + 3) % len(names)]):
        mesh = load_object(name)
        T = trimesh.transformations.random_rotation_matrix(rng.uniform(size=3))
        T[:3, 3] = rng.uniform(-0.2, 0.2, size=3)
        mesh.apply_transform(T)
        e = shape_error(mesh, mesh.copy(), n_samples=200)
        assert e.err == 0.0 and e.sym_diff == 0.0 and e.iou == 1.0, (name, e.err, e.iou)
    poly = box(0.1, 0.2, 0.3 + rng.uniform(), 0.5)
    e = shape_error(poly, poly)
    assert e.err == 0.0 and e.iou == 1.0


def test_error_in_range_for_overlapping_meshes():
    rng = np.random.default_rng(7)
    cube = trimesh.creation.box((0.08, 0.08, 0.08))
    for _ in range(20):
        other = cube.copy()
        other.apply_translation(rng.uniform(-1e-9, 1e-9, size=3))  # rounding-level moves
        e = shape_error(other, cube, n_samples=200)
        assert e.err >= 0.0 and 0.0 <= e.iou <= 1.0
