"""Tests of explore3d.export: mesh formats, the estimate URDF, point PLY files."""
import numpy as np
import pytest
import trimesh

from explore3d.export import (MESH_FORMATS, POINT_PROPERTIES, check_format, points_2d_if_planar, read_points_ply,
                              write_estimate_urdf, write_mesh, write_points_ply)
from explore3d.objects import load_object


@pytest.mark.parametrize("name", ["cube", "l_block"])
@pytest.mark.parametrize("fmt", MESH_FORMATS)
def test_mesh_formats_round_trip_volume(tmp_path, fmt, name):
    mesh = load_object(name)
    mesh.apply_translation([0.01, -0.02, 0.03])  # not centred: the frame must survive
    path = write_mesh(mesh, tmp_path / f"m.{fmt}", fmt)
    back = trimesh.load(str(path), force="mesh")
    assert back.is_watertight
    assert back.volume == pytest.approx(mesh.volume, rel=1e-5)
    np.testing.assert_allclose(back.bounds, mesh.bounds, atol=1e-6)
    assert not list(tmp_path.glob(".*part*"))  # no temporary left behind


def test_format_from_suffix_and_unknown_format(tmp_path):
    mesh = load_object("cube")
    write_mesh(mesh, tmp_path / "m.STL")
    assert trimesh.load(str(tmp_path / "m.STL")).volume == pytest.approx(mesh.volume, rel=1e-5)
    with pytest.raises(ValueError, match="obj, stl"):
        write_mesh(mesh, tmp_path / "m.xyz")
    with pytest.raises(ValueError):
        check_format("dae")
    assert not (tmp_path / "m.xyz").exists()


def _load_urdf_aabb(urdf):
    import pybullet as p

    cid = p.connect(p.DIRECT)
    try:
        body = p.loadURDF(str(urdf), useFixedBase=True, physicsClientId=cid)
        return np.array(p.getAABB(body, -1, physicsClientId=cid))
    finally:
        p.disconnect(cid)


@pytest.mark.parametrize("fmt", ["obj", "stl", "off", "glb"])
def test_estimate_urdf_loads_in_pybullet(tmp_path, fmt):
    mesh = load_object("box")
    mesh.apply_translation([0.2, 0.1, 0.05])
    name = f"estimate.{fmt}"
    write_mesh(mesh, tmp_path / name, fmt)
    urdf = write_estimate_urdf(name, tmp_path / "estimate.urdf", mass=0.2, mesh=mesh)
    text = urdf.read_text()
    used = "estimate.obj" if fmt in ("off", "glb") else name
    assert text.count(f'filename="{used}"') == 2  # visual + collision
    if fmt in ("off", "glb"):
        assert (tmp_path / "estimate.obj").is_file()
    aabb = _load_urdf_aabb(urdf)
    # PyBullet pads collision AABBs by a small margin
    np.testing.assert_allclose(aabb, mesh.bounds, atol=0.01)


def test_estimate_urdf_needs_mesh_for_other_formats(tmp_path):
    with pytest.raises(ValueError, match="OBJ"):
        write_estimate_urdf("estimate.ply", tmp_path / "e.urdf")
    with pytest.raises(ValueError, match="mass"):
        write_estimate_urdf("estimate.obj", tmp_path / "e.urdf", mass=0.0)


@pytest.mark.parametrize("binary", [True, False])
def test_points_ply_round_trip(tmp_path, binary):
    rng = np.random.default_rng(1)
    P = rng.uniform(-0.1, 0.1, size=(57, 3))
    wrap, att, link = rng.integers(0, 5, 57), rng.integers(0, 3, 57), rng.integers(0, 24, 57)
    write_points_ply(P, tmp_path / "p.ply", wrap, att, link, binary=binary)
    Q, props = read_points_ply(tmp_path / "p.ply", with_properties=True)
    assert Q.shape == (57, 3)
    np.testing.assert_allclose(Q, P, atol=1e-7)  # float32 storage
    assert set(props) == set(POINT_PROPERTIES)
    for name, ref in zip(POINT_PROPERTIES, (wrap, att, link)):
        np.testing.assert_array_equal(props[name], ref)


def test_points_ply_2d_gets_z_zero(tmp_path):
    P = np.array([[0.0, 0.0], [0.1, 0.0], [0.1, 0.1], [0.0, 0.1]])
    write_points_ply(P, tmp_path / "p.ply")
    Q, props = read_points_ply(tmp_path / "p.ply", with_properties=True)
    np.testing.assert_allclose(Q[:, 2], 0.0)
    np.testing.assert_allclose(points_2d_if_planar(Q), P, atol=1e-7)
    np.testing.assert_array_equal(props["wrap"], 0)


def test_points_ply_bad_input(tmp_path):
    with pytest.raises(ValueError, match="shape"):
        write_points_ply(np.zeros((4, 4)), tmp_path / "p.ply")
    with pytest.raises(ValueError, match="wrap"):
        write_points_ply(np.zeros((4, 3)), tmp_path / "p.ply", wrap=np.zeros(3))
    with pytest.raises(ValueError, match="NaN"):
        write_points_ply(np.full((4, 3), np.nan), tmp_path / "p.ply")
    assert not (tmp_path / "p.ply").exists()


def test_read_points_other_files(tmp_path):
    P = np.random.default_rng(2).normal(size=(20, 3))
    np.savetxt(tmp_path / "p.xyz", P)
    np.testing.assert_allclose(read_points_ply(tmp_path / "p.xyz"), P)
    mesh = load_object("cube")
    write_mesh(mesh, tmp_path / "m.stl")
    assert read_points_ply(tmp_path / "m.stl").shape[1] == 3
    with pytest.raises(FileNotFoundError):
        read_points_ply(tmp_path / "missing.ply")
    (tmp_path / "empty.ply").write_bytes(b"")
    with pytest.raises(ValueError, match="empty"):
        read_points_ply(tmp_path / "empty.ply")
    (tmp_path / "text.ply").write_text("hello, not a ply\n")
    with pytest.raises(ValueError):
        read_points_ply(tmp_path / "text.ply")


# --- pictures (explore3d.pictures; no simulation needed) ------------------------------------------

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def test_3d_pictures_are_pngs(tmp_path):
    import types

    from explore3d import pictures
    from explore3d.arm import ArmSpec
    from explore3d.metrics import shape_error

    truth = load_object("cube")
    est = load_object("sphere")
    err = shape_error(est, truth)
    pts = np.random.default_rng(0).uniform(-0.05, 0.05, size=(5000, 3))
    pictures.views_figure(est, truth, tmp_path / "views.png", points=pts, err=err)
    spec = ArmSpec(name="tiny", n_links=6)
    T = np.eye(4)
    T[:3, 3] = [-0.06, -0.05, 0.0]
    attempt = types.SimpleNamespace(q=np.full(6, 0.3), T_world_base=T)
    scene = pictures.scene_image(truth, spec, attempt, width=160, height=120)
    assert scene.shape == (120, 160, 3) and scene.dtype == np.uint8
    assert scene.std() > 1.0  # not a blank image
    pictures.overview_figure(tmp_path / "overview.png", {"error %": err.percent}, estimate_mesh=est,
                             truth_mesh=truth, points=pts, scene=scene)
    for name in ("views.png", "overview.png"):
        data = (tmp_path / name).read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 5000
