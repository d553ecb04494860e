"""Estimators for shapes not star-shaped about one centre (explore3d.reconstruction.estimators): geometric facts on
dense samples of known meshes (no simulation)."""
import numpy as np
import pytest
import trimesh

from explore3d.reconstruction import estimators as E
from explore3d import load_object
from explore3d.strategy.explore import rough_bound
from explore3d.geometry.metrics import volume_error


def samples(name, n=3000, seed=0):
    mesh = load_object(name)
    P, fi = trimesh.sample.sample_surface(mesh, n, seed=np.random.default_rng(seed))
    return mesh, P, mesh.face_normals[fi], np.zeros(len(P), dtype=int)


def percent(est, mesh):
    return 100.0 * volume_error(est, mesh) / mesh.volume


def test_l_block_is_not_star_shaped_about_its_rough_centre_but_the_alternatives_recover_it():
    mesh, P, N, w = samples("l_block")
    c, r = rough_bound(mesh.vertices)
    assert not mesh.contains([c])[0]  # the premise: the rough centre lies outside the L
    single = percent(E.single_centre(P, w, c, r), mesh)
    assert single > 15.0  # a star-shaped surface about an outside centre
    assert percent(E.multi_centre(P, w, c, r), mesh) < 4.0
    assert percent(E.implicit_surface(P, N, w, c, r), mesh) < 4.0


def test_implicit_surface_recovers_the_u_channel_whose_centre_lies_in_the_slot():
    mesh, P, N, w = samples("u_channel")
    c, r = rough_bound(mesh.vertices)
    assert percent(E.single_centre(P, w, c, r), mesh) > 100.0
    assert percent(E.implicit_surface(P, N, w, c, r), mesh) < 6.0


@pytest.mark.parametrize("name", ["cube", "sphere"])
def test_implicit_surface_of_a_convex_solid_is_close_to_it(name):
    mesh, P, N, w = samples(name)
    c, r = rough_bound(mesh.vertices)
    est = E.implicit_surface(P, N, w, c, r)
    assert est.is_watertight
    assert percent(est, mesh) < 2.0


def test_implicit_surface_moves_with_the_points():
    """A rigid motion of the points, normals and rough centre moves the estimate with them."""
    mesh, P, N, w = samples("l_block", n=2000)
    c, r = rough_bound(mesh.vertices)
    T = trimesh.transformations.euler_matrix(0.3, -0.5, 1.1)
    T[:3, 3] = [0.2, -0.1, 0.05]
    a = E.implicit_surface(P, N, w, c, r)
    b = E.implicit_surface(trimesh.transform_points(P, T), N @ T[:3, :3].T, w, T[:3, :3] @ c + T[:3, 3], r)
    moved = a.copy().apply_transform(T)
    assert abs(b.volume - a.volume) / a.volume < 0.01
    assert volume_error(b, moved) / a.volume < 0.03  # the voxel lattice is the world's, not the object's


def test_convex_carved_without_free_space_is_the_convex_hull():
    mesh, P, _, w = samples("l_block")
    c, r = rough_bound(mesh.vertices)
    est = E.convex_carved(P, c, r)
    assert est.volume == pytest.approx(trimesh.convex.convex_hull(P).volume, rel=1e-9)


def test_interior_centres_lie_inside_and_apart():
    mesh = load_object("u_channel")
    C = E.interior_centres(mesh, n=5)
    assert 1 <= len(C) <= 5
    assert mesh.contains(C).all()
    if len(C) > 1:
        d = np.linalg.norm(C[:, None] - C[None], axis=2)
        assert d[np.triu_indices(len(C), 1)].min() > 4e-3
