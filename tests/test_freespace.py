"""Free space, carving and probe targets: geometric facts (explore3d.reconstruction.freespace, .carve, .active)."""
import numpy as np
import pytest
import trimesh
from shapely.geometry import Point, Polygon

from explore3d.strategy.active import ProbeConfig, probe_poses, unsupported_targets
from explore3d.arm.spec import ArmSpec
from explore3d.reconstruction.carve import carve
from explore3d.reconstruction.freespace import SweptArea, is_free, load_swept, save_swept, swept_area
from explore3d.arm.kinematics import link_transforms

SMALL = ArmSpec(name="small16", n_links=16, link_length=0.02)


def _link_polygons(spec, q):
    """The links' rectangles in the base x-y plane (shapely), an independent construction."""
    T = link_transforms(spec, q)
    L, W = spec.link_length, spec.link_width
    corners = np.array([[0, -W / 2], [L, -W / 2], [L, W / 2], [0, W / 2]])
    return [Polygon(corners @ t[:2, :2].T + t[:2, 3]) for t in T]


@pytest.mark.parametrize("seed", [0, 1])
def test_free_points_lie_in_the_links_and_deep_link_points_are_free(seed):
    """is_free(p) implies p lies within the links' union (to half a pixel diagonal less the margin
    across the links; to half a pixel diagonal at the end faces a bend exposes, on its outer side),
    and points deeper than margin + a pixel diagonal inside a link, within the slab, are free."""
    rng = np.random.default_rng(seed)
    q = np.cumsum(rng.uniform(-0.1, 0.3, size=(40, SMALL.n_links)), axis=0) * 0.2  # a curling motion
    centre, radius = np.array([0.12, 0.05, 0.0]), 0.08
    a = swept_area(SMALL, q, np.eye(4), centre, radius)
    polys = [p for qi in q for p in _link_polygons(SMALL, qi)]
    from shapely.ops import unary_union

    swept = unary_union(polys)
    P = np.column_stack([centre[:2] + rng.uniform(-radius, radius, (4000, 2)), rng.uniform(-0.006, 0.006, 4000)])
    free = is_free([a], P)
    assert free.sum() > 200 and (~free).sum() > 200
    d_out = np.array([swept.distance(Point(x, y)) for x, y in P[:, :2]])
    assert np.all(d_out[free] <= a.pixel_m * np.sqrt(0.5) + 1e-9) and np.all(np.abs(P[free, 2]) <= SMALL.link_height / 2)
    # across the links (away from the joints) the margin holds: the outer sides of the chain
    sides = unary_union([p.buffer(-1e-3) for p in polys]).buffer(1e-3)  # the same union: sanity of the construction
    assert abs(sides.area - swept.area) < 0.02 * swept.area
    deep = unary_union([p.buffer(-(a.margin_m + a.pixel_m * np.sqrt(2.0)), join_style=2) for p in polys])
    inside = np.array([deep.contains(Point(x, y)) for x, y in P[:, :2]]) & (np.abs(P[:, 2]) <= a.half_height_m)
    inside &= np.linalg.norm(P[:, :2] - centre[:2], axis=1) < radius - 2 * a.pixel_m
    assert inside.sum() > 50 and np.all(free[inside])


def test_free_space_is_invariant_under_rigid_motion():
    rng = np.random.default_rng(3)
    q = np.cumsum(rng.uniform(0, 0.05, size=(30, SMALL.n_links)), axis=0)
    centre, radius = np.array([0.15, 0.02, 0.001]), 0.07
    P = np.column_stack([centre[:2] + rng.uniform(-radius, radius, (3000, 2)), rng.uniform(-0.006, 0.006, 3000)])
    from scipy.spatial.transform import Rotation

    G = np.eye(4)
    G[:3, :3] = Rotation.from_rotvec([0.3, -1.1, 0.7]).as_matrix()
    G[:3, 3] = [0.4, -0.2, 1.3]
    a = swept_area(SMALL, q, np.eye(4), centre, radius)
    b = swept_area(SMALL, q, G, G[:3, :3] @ centre + G[:3, 3], radius)
    fa, fb = is_free([a], P), is_free([b], P @ G[:3, :3].T + G[:3, 3])
    assert fa.sum() > 100 and np.mean(fa != fb) < 1e-3  # only points on a pixel border may flip


def test_save_and_load_round_trip(tmp_path):
    rng = np.random.default_rng(4)
    areas = [swept_area(SMALL, np.cumsum(rng.uniform(0, 0.05, size=(20, SMALL.n_links)), axis=0), np.eye(4),
                        [0.1, 0.0, z], 0.06) for z in (0.0, 0.03)]
    save_swept(areas, tmp_path / "f.npz")
    back = load_swept(tmp_path / "f.npz")
    assert len(back) == 2
    for x, y in zip(areas, back):
        assert np.array_equal(x.free, y.free) and np.allclose(x.T_world_base, y.T_world_base)
        assert (x.pixel_m, x.half_height_m, x.margin_m) == (y.pixel_m, y.half_height_m, y.margin_m)
    with pytest.raises(ValueError, match="free_space.npz"):
        load_swept(tmp_path / "missing.npz")


def _slab(half_height, T=np.eye(4), extent=0.1, pixel=1e-3):
    n = int(extent / pixel)
    return SweptArea(T_world_base=T, origin_m=np.full(2, -extent / 2), pixel_m=pixel, free=np.ones((n, n), bool),
                     half_height_m=half_height, margin_m=0.0)


def test_carving_a_slab_out_of_a_box():
    box = trimesh.creation.box((0.04, 0.04, 0.04))
    same = carve(box, [])
    assert same.mesh is box and same.carved_m3 == 0.0
    res = carve(box, [_slab(0.005)])  # the slab |z| <= 5 mm swept free
    assert res.mesh.volume == pytest.approx(0.04 * 0.04 * 0.03, rel=0.03)
    assert len(res.mesh.split()) == 2 and res.mesh.is_watertight
    # a thin sliver grazing the surface is not carved (the opening drops it)
    T = np.eye(4)
    T[2, 3] = 0.0205
    assert carve(box, [_slab(0.0007, T)]).carved_m3 == 0.0


def test_unsupported_targets_and_their_planes():
    box = trimesh.creation.box((0.08, 0.08, 0.08))
    top = np.column_stack([np.random.default_rng(0).uniform(-0.04, 0.04, (400, 2)), np.full(400, 0.04)])
    P, N, d = unsupported_targets(box, top, min_distance_m=0.02, exclusion_m=0.01, k=5)
    assert len(P) == 5 and np.all(d > 0.02) and np.all(np.diff(d) <= 0)
    assert np.all(np.abs(box.nearest.signed_distance(P)) < 1e-9) and np.all(P[:, 2] < 0.04 - 0.02 + 1e-9)
    assert min(np.linalg.norm(P[i] - P[j]) for i in range(5) for j in range(i)) > 0.01
    # supported everywhere: nothing to aim at
    dense = trimesh.sample.sample_surface(box, 20000, seed=1)[0]
    assert len(unsupported_targets(box, dense, 0.02, 0.01, 5)[0]) == 0
    # previous targets are excluded
    P2 = unsupported_targets(box, top, 0.02, 0.01, 5, previous=P)[0]
    assert min(np.linalg.norm(P2[:, None] - P[None], axis=2).ravel()) > 0.01
    poses = probe_poses(P, N, np.zeros(3), 0.075, 0.008, orientations=2, across_depth_m=0.005)
    assert len(poses) == 3 * len(P)
    for i, (p, n) in enumerate(zip(P, N)):
        for w in poses[3 * i: 3 * i + 2]:  # planes containing the target and its normal
            z, o = w.T_world_base[:3, 2], w.T_world_base[:3, 3]
            assert abs((p - o) @ z) < 1e-9 and abs(n @ z) < 1e-9
        z, o = poses[3 * i + 2].T_world_base[:3, 2], poses[3 * i + 2].T_world_base[:3, 3]
        assert abs(abs(n @ z) - 1) < 1e-9 and abs((p - 0.005 * n - o) @ z) < 1e-9  # across, 5 mm beneath


def test_volume_at_stake_of_a_square_with_one_contact_at_its_centre():
    """Known answer: the mean distance from the centre of a square of side L to its points is
    L (sqrt(2) + ln(1 + sqrt(2))) / 6, so the volume at stake is L^2 times that."""
    from explore3d.strategy.active import surface_stake

    L = 0.1
    sq = trimesh.Trimesh([[0, 0, 0], [L, 0, 0], [L, L, 0], [0, L, 0]], [[0, 1, 2], [0, 2, 3]], process=False)
    P, N, d, area = surface_stake(sq, [[L / 2, L / 2, 0.0]], samples=40000, seed=3)
    expected = L ** 3 * (np.sqrt(2) + np.log(1 + np.sqrt(2))) / 6
    assert area == pytest.approx(L * L / 40000) and np.allclose(np.abs(N[:, 2]), 1.0)
    assert area * d.sum() == pytest.approx(expected, rel=0.01)
    # the same square moved and turned: the same stake (rigid motion)
    T = trimesh.transformations.random_rotation_matrix(np.random.default_rng(1).random(3))
    T[:3, 3] = [0.3, -0.2, 0.5]
    sq2 = sq.copy().apply_transform(T)
    c2 = trimesh.transform_points([[L / 2, L / 2, 0.0]], T)
    _, _, d2, a2 = surface_stake(sq2, c2, samples=40000, seed=3)
    assert a2 * d2.sum() == pytest.approx(area * d.sum(), rel=1e-6)


def test_stake_targets_need_no_link_length_floor_and_prefer_the_widest_gap():
    """The bunny as the estimate, touched everywhere to within 20 mm (the former floor) except two
    patches left bare: the former rule (farther than a link length) finds nothing to aim at; the
    volume at stake finds targets, the first in the wider patch."""
    from explore3d.world.objects import load_object

    bunny = load_object("pybullet_data:bunny.obj", size=0.1)
    S = trimesh.sample.sample_surface_even(bunny, 3000, seed=0)[0]
    wide, narrow = S[np.argmin(S[:, 0])], S[np.argmax(S[:, 0])]
    keep = (np.linalg.norm(S - wide, axis=1) > 0.016) & (np.linalg.norm(S - narrow, axis=1) > 0.01)
    C = S[keep]
    assert len(unsupported_targets(bunny, C, 0.02, 0.01, 5)[0]) == 0  # the former default: no target
    P, N, d = unsupported_targets(bunny, C, 0.0, 0.01, 3, rank="stake")
    assert len(P) == 3 and np.all(d > 0)
    assert np.linalg.norm(P[0] - wide) < 0.016
    with pytest.raises(ValueError, match="rank"):
        unsupported_targets(bunny, C, 0.0, 0.01, 1, rank="volume")


def test_finger_lies_alongside_the_slot_wall_in_empty_space_and_curls_onto_it():
    """The U-channel as the estimate, a target on a slot wall: the finger's straight arm (link
    cross-section plus the gap) lies outside the estimate, its base outside the rough bound, the
    arm runs along the wall and curls towards it; a target on the wall of a closed pocket gets none."""
    from explore3d.strategy.active import finger_poses
    from explore3d.arm.urdf import load_arm
    from explore3d.arm.kinematics import link_transforms
    from explore3d.world.objects import u_channel

    spec = load_arm("default")
    u = u_channel()  # slot x in [-20, 20] mm, open towards +y, along z
    p, n = np.array([-0.02, 0.01, 0.0]), np.array([1.0, 0.0, 0.0])  # on the slot's left wall
    (pose,) = finger_poses([p], [n], u, np.zeros(3), 0.075, spec)
    T = pose.T_world_base
    assert np.linalg.norm(T[:3, 3]) > 0.075
    e, y = T[:3, 0], T[:3, 1]
    assert abs(e @ n) < np.sin(np.radians(15)) + 1e-9 and y @ n < -0.9  # alongside, curling onto the wall
    frames = link_transforms(spec, np.zeros(spec.n_links), T)
    s = np.linspace(0, spec.link_length, 5)
    axis = (frames[:, None, :3, 3] + s[None, :, None] * frames[:, None, :3, 0]).reshape(-1, 3)
    assert not u.contains(axis).any()
    tip = frames[-1, :3, 3] + spec.link_length * frames[-1, :3, 0]
    assert np.linalg.norm(tip - p) < 0.02  # the tip beside the target
    in_slot = axis[(np.abs(axis[:, 0]) < 0.02) & (axis[:, 1] > -0.02) & (axis[:, 1] < 0.04) & (np.abs(axis[:, 2]) < 0.04)]
    assert len(in_slot) and np.abs(in_slot[:, 0] - p[0]).max() < 0.012  # along the wall, not across the slot
    # a closed pocket: a box with a sealed cavity, the target on the cavity's wall
    box = trimesh.creation.box((0.08, 0.08, 0.08)).difference(trimesh.creation.box((0.03, 0.03, 0.03)),
                                                               engine="manifold")
    assert finger_poses([[-0.015, 0.0, 0.0]], [[1.0, 0.0, 0.0]], box, np.zeros(3), 0.075, spec) == []


def test_probe_config_rejects_bad_values():
    with pytest.raises(ValueError, match="rounds"):
        ProbeConfig(rounds=-1)
    with pytest.raises(ValueError, match="min_distance_m"):
        ProbeConfig(min_distance_m=-0.01)
    with pytest.raises(ValueError, match="fingers"):
        ProbeConfig(fingers=-1)
    with pytest.raises(ValueError, match="rank"):
        ProbeConfig(rank="farthest")
    with pytest.raises(ValueError, match="stop_stake"):
        ProbeConfig(stop_stake=-0.1)


def test_the_swept_space_of_a_real_exploration_never_holds_the_object():
    """Wraps around the cube in PyBullet: no point inside the cube is free, yet the swept space
    reaches to within a couple of millimetres of its faces."""
    from explore3d.strategy.explore import ExploreConfig
    from explore3d.world.explore import explore
    from explore3d.world.objects import cube

    m = cube()
    ex = explore(m, SMALL, ExploreConfig(directions=4, angles=1, jobs=1, probes=None))
    assert len(ex.swept) == 4
    inside = trimesh.sample.volume_mesh(m, 20000)
    assert not is_free(ex.swept, inside).any()
    near = trimesh.sample.sample_surface(m, 4000, seed=0)[0]
    out = near + 0.002 * np.sign(near) * (np.abs(near) > 0.0399)
    assert is_free(ex.swept, out).sum() > 20  # measured 73 of 4000 (4 wraps' slabs cover ~2% of the shell)


# --- fins the carving leaves (explore3d.reconstruction.carve.trim_fins) ------------------------------

def _box_with_fin(thickness: float):
    """A 40 mm box with a plate ``thickness`` m thick, 20 mm wide, standing 10 mm out of its +x face."""
    box = trimesh.creation.box((0.04, 0.04, 0.04))
    plate = trimesh.creation.box((0.012, thickness, 0.02))
    plate.apply_translation([0.02 + 0.005, 0.0, 0.0])  # 2 mm inside the face, 10 mm out
    return box, box.union(plate, engine="manifold")


def test_a_thin_fin_is_trimmed_and_the_body_kept():
    """A 1 mm plate 10 mm out of a box: trimmed to within a voxel of the face; the box's volume,
    faces and edges stay (the trim only rounds nothing off them)."""
    from explore3d.reconstruction.carve import FIN_VOXEL_M, trim_fins

    box, finned = _box_with_fin(0.001)
    out, trimmed = trim_fins(finned)
    assert out.is_watertight and out.body_count == 1
    assert trimmed == pytest.approx(finned.volume - box.volume, rel=0.5)
    assert out.bounds[1, 0] < 0.02 + 2 * FIN_VOXEL_M  # the fin gone (it reached x = 30 mm)
    assert out.volume == pytest.approx(box.volume, rel=2e-3)
    assert out.bounds[0] == pytest.approx(box.bounds[0], abs=1e-9)  # the other faces untouched


def test_a_wall_thicker_than_the_fin_width_is_kept_and_a_plain_box_returned_as_it_is():
    from explore3d.reconstruction.carve import DEFAULT_FIN_M, trim_fins

    _, walled = _box_with_fin(3 * DEFAULT_FIN_M)  # 4.5 mm: thicker than the ball of radius 1.5 mm
    out, trimmed = trim_fins(walled)
    assert out is walled and trimmed == 0.0
    box = trimesh.creation.box((0.04, 0.04, 0.04))
    assert trim_fins(box) == (box, 0.0)


def test_trimming_never_adds_volume_and_moves_with_the_mesh():
    """The trimmed estimate lies inside the one given (it never enters free space the estimate
    left out), and a rigid motion of the input moves the output with it (to a voxel)."""
    from explore3d.reconstruction.carve import FIN_VOXEL_M, trim_fins

    _, finned = _box_with_fin(0.001)
    out, _ = trim_fins(finned)
    P = out.sample(2000, seed=1)
    inward = P - 1e-4 * out.face_normals[out.nearest.on_surface(P)[2]]
    assert finned.contains(inward).all()
    T = trimesh.transformations.random_rotation_matrix(np.random.default_rng(3).random(3))
    T[:3, 3] = [0.013, -0.021, 0.007]
    moved = finned.copy()
    moved.apply_transform(T)
    out_moved, _ = trim_fins(moved)
    assert out_moved.volume == pytest.approx(out.volume, rel=5e-3)
    back = out_moved.copy()
    back.apply_transform(np.linalg.inv(T))
    assert np.abs(back.bounds - out.bounds).max() < 2 * FIN_VOXEL_M


def test_trim_fins_refuses_bad_sizes():
    from explore3d.reconstruction.carve import trim_fins

    box = trimesh.creation.box((0.04, 0.04, 0.04))
    with pytest.raises(ValueError, match="fin_m"):
        trim_fins(box, 0.0)
    with pytest.raises(ValueError, match="fin_m"):
        carve(box, [], fin_m=-1.0)
