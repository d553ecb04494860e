"""Tests for explore3d.world.objects: geometric facts about the built-ins, and load_object's contract."""
from __future__ import annotations

import logging

import numpy as np
import pytest
import trimesh

from explore3d.world import objects
from explore3d.world.objects import BUILTIN_OBJECTS, MeshError, builtin_object_names, cross_section, load_object, object_size, regular_polygon, square
from explore3d.core.tolerances import STL_FLOAT32_RTOL

REQUIRED = {"cube", "cylinder", "sphere", "box", "capsule", "cone", "l_block", "u_channel", "star_prism"}
CONCAVE = {"l_block", "u_channel", "star_prism"}
# float64 sums of a few hundred terms of size ~1e-4 m^3: relative rounding far below 1e-12
EXACT = 1e-12


def polygon_area(r, n):
    """Area of the regular n-gon of circumradius r."""
    return 0.5 * n * r**2 * np.sin(2 * np.pi / n)


# ------------------------------------------------------------------------------------------
# builders
# ------------------------------------------------------------------------------------------


def test_registry_has_required_names():
    assert REQUIRED <= set(builtin_object_names())
    for name, info in BUILTIN_OBJECTS.items():
        assert info.name == name and info.description


@pytest.mark.parametrize("name", sorted(BUILTIN_OBJECTS))
def test_builtin_is_closed_outward_volume(name):
    mesh = BUILTIN_OBJECTS[name].builder()
    assert mesh.is_watertight
    assert mesh.is_winding_consistent
    assert mesh.volume > 0
    # outward: the divergence theorem with outward normals gives the positive volume, and
    # inverting the mesh flips it
    inv = mesh.copy()
    inv.invert()
    assert inv.volume == pytest.approx(-mesh.volume, rel=EXACT)
    lo, hi = mesh.bounds
    assert hi[2] + lo[2] == pytest.approx(0.0, abs=1e-12)  # z centred on the bounding box
    if name == "star_prism":  # star centred on its own centre (its centroid)
        assert np.allclose(mesh.center_mass[:2], 0.0, atol=1e-12)
    else:
        assert np.allclose(lo + hi, 0.0, atol=1e-12)
    ext = hi - lo
    assert 0.04 <= ext.max() <= 0.13  # paper-sized objects, metres


def test_cube_volume_exact():
    assert objects.cube().volume == pytest.approx(0.08**3, rel=EXACT)
    assert objects.cube(0.05).volume == pytest.approx(0.05**3, rel=EXACT)


def test_box_volume_exact():
    assert objects.box((0.1, 0.06, 0.04)).volume == pytest.approx(0.1 * 0.06 * 0.04, rel=EXACT)


def test_cylinder_is_the_100gon_prism():
    mesh = objects.cylinder()
    assert mesh.volume == pytest.approx(polygon_area(0.063, 100) * 0.08, rel=EXACT)
    # and the prism's cross-section is exactly regular_polygon(): same vertex set
    sec = cross_section(mesh, 0.013)
    ref = regular_polygon(0.063, 100)
    assert sec.symmetric_difference(ref).area <= 1e-12 * ref.area


def test_cone_volume_exact_and_apex_up():
    mesh = objects.cone(radius=0.05, height=0.08, sections=64)
    assert mesh.volume == pytest.approx(polygon_area(0.05, 64) * 0.08 / 3.0, rel=EXACT)
    top = mesh.vertices[mesh.vertices[:, 2] > 0]
    assert np.allclose(top, [0.0, 0.0, 0.04])


@pytest.mark.parametrize("subdivisions", [1, 2, 3, 4])
def test_sphere_volume_within_inscribed_polyhedron_bounds(subdivisions):
    r = 0.05
    mesh = objects.sphere(r, subdivisions)
    assert np.allclose(np.linalg.norm(mesh.vertices, axis=1), r, rtol=1e-12)
    # vertices on the sphere -> the polyhedron is inside the ball; it contains the ball of
    # radius d = distance of the nearest face plane = sqrt(r^2 - rho^2), rho the largest
    # triangle circumradius
    tri = mesh.triangles
    a = np.linalg.norm(tri[:, 1] - tri[:, 2], axis=1)
    b = np.linalg.norm(tri[:, 0] - tri[:, 2], axis=1)
    c = np.linalg.norm(tri[:, 0] - tri[:, 1], axis=1)
    rho = (a * b * c / (4.0 * mesh.area_faces)).max()
    d = np.sqrt(r**2 - rho**2)
    ball = 4.0 / 3.0 * np.pi
    assert ball * d**3 < mesh.volume < ball * r**3


def test_sphere_converges_with_subdivision():
    exact = 4.0 / 3.0 * np.pi * 0.05**3
    deficits = [exact - objects.sphere(0.05, k).volume for k in range(5)]
    assert all(d > 0 for d in deficits)
    # second-order convergence: each subdivision halves the edge length, the deficit drops ~4x
    ratios = np.array(deficits[:-1]) / np.array(deficits[1:])
    assert np.all(ratios[1:] > 3.5)


def test_capsule_geometry_and_volume_bounds():
    r, h = 0.03, 0.10
    mesh = objects.capsule(r, h)
    hc = h - 2 * r  # straight part
    assert mesh.extents == pytest.approx([2 * r, 2 * r, h], rel=1e-12)
    # every vertex on the capsule surface: distance r from the axis segment
    v = mesh.vertices
    zc = np.clip(v[:, 2], -hc / 2, hc / 2)
    dist = np.linalg.norm(v - np.column_stack([np.zeros_like(zc), np.zeros_like(zc), zc]), axis=1)
    assert np.allclose(dist, r, rtol=1e-9)
    analytic = np.pi * r**2 * hc + 4.0 / 3.0 * np.pi * r**3
    assert mesh.volume < analytic
    # inscribed convex polytope containing the axis segment: it contains the capsule of radius
    # d = min over face planes of the plane's distance to the segment's end points
    n = mesh.face_normals
    p0 = mesh.triangles[:, 0]
    ends = np.array([[0, 0, -hc / 2], [0, 0, hc / 2]])
    d = min(np.einsum("ij,ij->i", n, p0 - e).min() for e in ends)
    assert 0 < d < r
    assert mesh.volume > np.pi * d**2 * hc + 4.0 / 3.0 * np.pi * d**3


def test_capsule_rejects_height_below_diameter():
    with pytest.raises(ValueError, match="2\\*radius"):
        objects.capsule(0.03, 0.05)


@pytest.mark.parametrize(
    "name, volume",
    [
        # 80x80 mm square minus a 40x40 mm notch, 80 mm deep
        ("l_block", (0.08**2 - 0.04**2) * 0.08),
        # 80x80 mm minus a 40 mm wide, 60 mm deep slot, 80 mm long
        ("u_channel", (0.08 * 0.08 - 0.04 * 0.06) * 0.08),
        # 10 triangles fanned from the centre, each 1/2 R r sin(pi/5), 40 mm thick
        ("star_prism", 10 * 0.5 * 0.05 * 0.025 * np.sin(np.pi / 5) * 0.04),
    ],
)
def test_concave_volumes_by_hand(name, volume):
    mesh = BUILTIN_OBJECTS[name].builder()
    assert mesh.volume == pytest.approx(volume, rel=EXACT)
    assert not mesh.is_convex
    assert mesh.volume < mesh.convex_hull.volume * 0.95


def test_object_size_of_cube():
    size = object_size(objects.cube(0.08))
    assert np.allclose(size["extents"], 0.08)
    assert size["volume"] == pytest.approx(0.08**3)
    assert size["bounding_radius"] == pytest.approx(np.sqrt(3) * 0.04)
    moved = objects.cube(0.08).apply_translation([1.0, 2.0, 3.0])
    assert object_size(moved)["bounding_radius"] == pytest.approx(np.sqrt(3) * 0.04)


# ------------------------------------------------------------------------------------------
# planar helpers
# ------------------------------------------------------------------------------------------


def test_planar_helpers():
    assert square(0.08).area == pytest.approx(0.0064, rel=EXACT)
    assert square().exterior.is_ccw
    poly = regular_polygon(0.063, 100)
    assert poly.area == pytest.approx(polygon_area(0.063, 100), rel=EXACT)
    assert poly.exterior.is_ccw


def test_cross_section_matches_profiles():
    sec = cross_section(objects.cube(0.08), z=0.02)
    assert sec.symmetric_difference(square(0.08)).area <= 1e-12
    sec = cross_section(objects.u_channel(), z=-0.01)
    assert sec.symmetric_difference(objects.u_profile()).area <= 1e-12
    sec = cross_section(objects.sphere(0.05, 4), z=0.0)
    assert 0.95 * np.pi * 0.05**2 < sec.area < np.pi * 0.05**2


def test_cross_section_misses_mesh():
    with pytest.raises(ValueError, match="does not cut"):
        cross_section(objects.cube(0.08), z=0.5)


# ------------------------------------------------------------------------------------------
# load_object
# ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(REQUIRED))
def test_load_builtin(name):
    mesh = load_object(name)
    assert mesh.volume == pytest.approx(BUILTIN_OBJECTS[name].builder().volume, rel=EXACT)


@pytest.mark.parametrize("ext", ["stl", "obj", "ply"])
def test_file_round_trip(tmp_path, ext, caplog):
    ref = objects.l_block()
    path = tmp_path / f"l_block.{ext}"
    ref.export(path)
    with caplog.at_level(logging.WARNING, logger="explore3d.world.objects"):
        mesh = load_object(path)
    assert mesh.volume == pytest.approx(ref.volume, rel=STL_FLOAT32_RTOL)
    assert np.allclose(mesh.bounds, ref.bounds, atol=1e-7)
    assert mesh.is_watertight
    assert not caplog.records  # a clean file needs no repair


def test_frame_preserved(tmp_path):
    ref = objects.cube(0.05).apply_translation([0.3, -0.2, 0.1])
    path = tmp_path / "moved.stl"
    ref.export(path)
    mesh = load_object(str(path))
    assert np.allclose(mesh.bounds, ref.bounds, atol=1e-7)
    # scaling is about the file's origin, not the mesh centre
    mesh2 = load_object(path, scale=2.0)
    assert np.allclose(mesh2.bounds, 2.0 * ref.bounds, atol=1e-7)


@pytest.mark.parametrize("s", [0.5, 2.0, 10.0])
def test_scale_multiplies_volume_by_cube(s):
    assert load_object("star_prism", scale=s).volume == pytest.approx(s**3 * objects.star_prism().volume, rel=1e-12)


@pytest.mark.parametrize("size", [0.02, 0.1, 1.0])
def test_size_sets_longest_side(size):
    mesh = load_object("box", size=size)
    assert mesh.extents.max() == pytest.approx(size, rel=1e-12)
    ratio = mesh.extents / objects.box().extents  # uniform scaling
    assert np.allclose(ratio, ratio[0])


def test_pybullet_data_prefix(caplog):
    with caplog.at_level(logging.WARNING, logger="explore3d.world.objects"):
        mesh = load_object("pybullet_data:cube.obj")
    # pybullet's cube.obj is a 1 m cube whose vertices are split per face by the texture
    # coordinates; merging them closes it
    assert mesh.is_watertight and mesh.volume == pytest.approx(1.0, rel=1e-9)
    assert any("merged" in r.getMessage() for r in caplog.records)
    duck = load_object("pybullet_data:duck_vhacd.obj", scale=0.05)
    assert duck.is_watertight and duck.volume > 0
    assert 0.05 < duck.extents.max() < 0.1  # the URDF's 0.05 scale makes it ~83 mm long


def _open_cylinder():
    mesh = objects.cylinder(0.03, 0.05, 40)
    top = mesh.face_normals[:, 2] > 0.5  # the 40-gon cap: a 40-edge hole once removed
    return trimesh.Trimesh(mesh.vertices, mesh.faces[~top])


def _write(tmp_path, name, content):
    path = tmp_path / name
    if isinstance(content, trimesh.Trimesh):
        content.export(path)
    else:
        path.write_text(content)
    return path


@pytest.mark.parametrize(
    "make_spec, kwargs, error, match",
    [
        (lambda d: d / "missing.stl", {}, MeshError, "not found"),
        (lambda d: _write(d, "notes.txt", "hello world\n"), {}, MeshError, "cannot read"),
        (lambda d: _write(d, "empty.stl", ""), {}, MeshError, "no triangles"),
        (lambda d: _write(d, "garbage.obj", "this is not a mesh\n"), {}, MeshError, "no triangles"),
        (lambda d: _write(d, "open.stl", _open_cylinder()), {}, MeshError, "not a closed volume .*open edges"),
        (lambda d: "teapot", {}, MeshError, "unknown object 'teapot'.*cube"),
        (lambda d: "pybullet_data:no_such_file.obj", {}, MeshError, "pybullet_data has no file"),
        (lambda d: "cube", {"scale": 0.0}, ValueError, "scale"),
        (lambda d: "cube", {"scale": -1.0}, ValueError, "scale"),
        (lambda d: "cube", {"size": float("nan")}, ValueError, "size"),
        (lambda d: "cube", {"scale": 2.0, "size": 0.1}, ValueError, "not both"),
    ],
)
def test_load_errors(tmp_path, make_spec, kwargs, error, match):
    with pytest.raises(error, match=match):
        load_object(make_spec(tmp_path), **kwargs)


def test_mesh_error_is_value_error():
    assert issubclass(MeshError, ValueError)


def test_flipped_faces_are_repaired_with_warning(tmp_path, caplog):
    ref = objects.cube(0.08)
    faces = ref.faces.copy()
    faces[[0, 5, 7]] = faces[[0, 5, 7]][:, ::-1]
    path = _write(tmp_path, "flipped.stl", trimesh.Trimesh(ref.vertices, faces, process=False))
    with caplog.at_level(logging.WARNING, logger="explore3d.world.objects"):
        mesh = load_object(path)
    assert mesh.is_winding_consistent and mesh.is_watertight
    assert mesh.volume == pytest.approx(ref.volume, rel=STL_FLOAT32_RTOL)
    messages = " ".join(r.getMessage() for r in caplog.records)
    assert "flipped.stl" in messages and "flipped the winding of 3 faces" in messages


def test_inside_out_mesh_is_repaired(tmp_path, caplog):
    ref = objects.cylinder()
    inv = ref.copy()
    inv.invert()
    path = _write(tmp_path, "inside_out.ply", inv)
    with caplog.at_level(logging.WARNING, logger="explore3d.world.objects"):
        mesh = load_object(path)
    assert mesh.volume == pytest.approx(ref.volume, rel=STL_FLOAT32_RTOL)
    assert any("inside-out surface outward" in r.getMessage() for r in caplog.records)


def test_small_hole_is_filled(tmp_path, caplog):
    ref = objects.cube(0.08)
    path = _write(tmp_path, "holed.stl", trimesh.Trimesh(ref.vertices, ref.faces[1:], process=False))
    with caplog.at_level(logging.WARNING, logger="explore3d.world.objects"):
        mesh = load_object(path)
    assert mesh.is_watertight
    assert mesh.volume == pytest.approx(ref.volume, rel=STL_FLOAT32_RTOL)
    assert any("filled holes" in r.getMessage() for r in caplog.records)
