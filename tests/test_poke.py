"""Tip probing (explore3d.strategy.poke): the hook's geometry, where pokes start, a poke onto a
known face localised on the tip, pokes into a star notch the wraps bridge, and the tip following that
face."""
import math

import numpy as np
import pytest
import trimesh

from explore3d import load_arm
from explore3d.arm.kinematics import link_transforms
from explore3d.arm.spec import ArmSpec
from explore3d.core.settings import SimConfig
from explore3d.feeling.contacts import MAX_UNCERTAINTY_M, contact_uncertainty_m, localise_attempts
from explore3d.robot.sensing import SensorConfig
from explore3d.strategy.active import ProbeConfig
from explore3d.strategy.encircle import ControlConfig
from explore3d.strategy.poke import arm_points, hook_angles, poke_frame, poke_poses, run_poke, tip_point
from explore3d.world.band import cached_band
from explore3d.world import objects
from explore3d.world.sim import ArmSimulation

SPEC = load_arm("default")
GRAVITY = np.array([0.0, 0.0, -9.81])


@pytest.mark.parametrize("spec", [SPEC, ArmSpec(name="small16", n_links=16, link_length=0.02)])
def test_the_hooks_tip_moves_along_its_own_axis(spec):
    """Turning the base joint moves the tip's distal face centre along the tip link's axis (finite
    difference against the heading), and only the last joints are bent, within their limits."""
    q = hook_angles(spec)
    p, h = tip_point(spec, q)
    dq = np.zeros(spec.n_links)
    dq[0] = 1e-7
    v = (tip_point(spec, q + dq)[0] - p) / 1e-7
    assert np.allclose(v / np.linalg.norm(v), [math.cos(h), math.sin(h)], atol=1e-6)
    assert np.all(q[: spec.n_links - 3] == 0) and np.all(q[-3:] > 0) and np.all(q <= spec.joint_upper)


def test_the_poke_frame_brings_the_tip_to_the_target_along_the_inward_normal():
    """At the base angle of the standoff the tip's face centre is on the target, the tip link along
    -n; at base angle 0 it lies the standoff back along n (to the arc's sag); invariant under a
    rigid motion of target, normal and plane."""
    q = hook_angles(SPEC)
    R = float(np.linalg.norm(tip_point(SPEC, q)[0]))
    rng = np.random.default_rng(3)
    for _ in range(5):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        z = np.cross(n, rng.normal(size=3))
        z /= np.linalg.norm(z)
        target = rng.normal(size=3) * 0.05
        T = poke_frame(SPEC, q, target, n, z, 0.02)
        assert np.allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-12) and np.linalg.det(T[:3, :3]) > 0
        at = q.copy()
        at[0] = 0.02 / R
        L = link_transforms(SPEC, at, T)[-1]
        assert np.allclose(L[:3, :3] @ [SPEC.link_length, 0, 0] + L[:3, 3], target, atol=1e-12)
        assert np.allclose(L[:3, 0], -n, atol=1e-9)
        L0 = link_transforms(SPEC, q, T)[-1]
        tip0 = L0[:3, :3] @ [SPEC.link_length, 0, 0] + L0[:3, 3]
        assert abs((tip0 - target) @ n - 0.02) < 0.02 ** 2 / R and np.linalg.norm(tip0 - target) < 0.0201


def test_pokes_start_outside_the_estimate_with_the_base_outside_the_bound():
    """Pokes at targets on a box estimate: the arm's start (cross section plus the gap) lies
    outside the estimate, the base outside the rough bound; a target at the bottom of a pocket
    narrower than the tip's clear section and deeper than the largest standoff gets none."""
    est = trimesh.creation.box((0.1, 0.1, 0.1))
    targets = [[0.05, 0.01, 0.015], [0.0, -0.01, 0.05], [0.01, -0.05, -0.02]]
    normals = [[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]
    poses = poke_poses(targets, normals, [0.02] * 3, est, np.zeros(3), 0.09, SPEC)
    assert len(poses) == 3
    for p in poses:
        assert np.linalg.norm(p.T_world_base[:3, 3]) > 0.09
        assert not est.contains(arm_points(SPEC, p.q0, p.T_world_base, 0.003).reshape(-1, 3)).any()
    slot = est.difference(trimesh.creation.box((0.01, 0.01, 0.08), trimesh.transformations.translation_matrix(
        [0, 0, 0.03])), engine="manifold")  # a 10 x 10 mm pocket 60 mm deep in the top face
    bottom = ([[0.0, 0.0, -0.01]], [[0, 0, 1.0]], [0.02])
    assert poke_poses(*bottom, slot, np.zeros(3), 0.09, SPEC) == []  # deeper than the largest standoff
    # unless the pocket is space the wraps swept (proven empty)
    assert len(poke_poses(*bottom, slot, np.zeros(3), 0.09, SPEC, free=lambda P: np.ones(len(P), bool))) == 1


def test_a_tip_poke_onto_a_flat_face_is_localised_on_the_tip_within_a_millimetre():
    """The default arm pokes the top face of a fixed 80 mm cube 10 mm inside the estimate's face:
    the base joint's sweep detects the touch, the settled reading is still, and the contact is
    localised on the tip link within 1 mm of the face, within the tip's distal face in the plane."""
    cube = trimesh.creation.box((0.08, 0.08, 0.08))
    est = trimesh.creation.box((0.1, 0.1, 0.1))
    target, n = np.array([0.005, -0.01, 0.05]), np.array([0.0, 0.0, 1.0])
    (pose,) = poke_poses([target], [n], [0.03], est, np.zeros(3), 0.09, SPEC)
    band = cached_band(SPEC, ControlConfig(), SimConfig(), SensorConfig(), False)
    with ArmSimulation(SPEC, cube.vertices, cube.faces, SimConfig()) as world:
        robot = world.robot(SensorConfig())
        robot.reseed((0, 0))
        att = run_poke(robot, pose.T_world_base, pose.q0, pose.stop_rad, band)
    assert att.contact[0] and len(att.moments) == 1 and att.moments[0].still
    cs = localise_attempts(SPEC, [att], GRAVITY, SensorConfig())
    assert len(cs) == 1 and cs.link[0] == SPEC.n_links - 1
    assert abs(cs.points[0, 2] - 0.04) < 1e-3  # on the face
    L = link_transforms(SPEC, att.moments[0].reading.q, pose.T_world_base)[-1]
    face = L[:3, :3] @ [SPEC.link_length, 0, 0] + L[:3, 3]  # the tip's distal face centre (the model)
    assert np.linalg.norm((cs.points[0] - face)[:2]) < SPEC.link_width / 2 + 1e-3
    assert cs.force_n[0] > 0.3


def test_a_star_prism_notch_wider_than_the_tip_gets_contacts_inside_it():
    """The star prism's notch (a V of 125 deg, 15 mm deep) is bridged by wraps; the estimate here is
    the star's convex hull, as if wraps alone had made it.  One poke at each flank, a third of the
    way out from the notch's floor, on the fixed star: each is localised on the tip within 1 mm of
    the true flank and at least 5 mm inside the hull, where no wrap reaches."""
    star = objects.star_prism()
    hull = star.convex_hull
    top = star.vertices[star.vertices[:, 2] > 0][:, :2]
    r = np.linalg.norm(top, axis=1)
    floor = top[np.isclose(r, 0.025)][0]  # the notch's innermost corner
    outer = top[np.isclose(r, 0.05)]
    tips = outer[np.argsort(np.linalg.norm(outer - floor, axis=1))[:2]]  # the notch's two points
    targets, normals = [], []
    for tip in tips:
        d = (tip - floor) / np.linalg.norm(tip - floor)
        n = np.array([d[1], -d[0]])
        n = n if n @ (tips.mean(axis=0) - floor) > 0 else -n  # out of the star, into the notch
        targets.append([*(floor + (tip - floor) / 3), 0.0])
        normals.append([*n, 0.0])
    poses = poke_poses(targets, normals, [0.01, 0.01], hull, np.zeros(3), 0.075, SPEC)
    assert len(poses) == 2
    band = cached_band(SPEC, ControlConfig(), SimConfig(), SensorConfig(), False)
    with ArmSimulation(SPEC, star.vertices, star.faces, SimConfig()) as world:
        robot = world.robot(SensorConfig())
        attempts = []
        for k, pose in enumerate(poses):
            robot.reseed((0, k))
            attempts.append(run_poke(robot, pose.T_world_base, pose.q0, pose.stop_rad, band))
    assert all(a.contact[0] for a in attempts)
    cs = localise_attempts(SPEC, attempts, GRAVITY, SensorConfig())
    assert len(cs) == 2 and (cs.link == SPEC.n_links - 1).all()
    for p, tip in zip(cs.points, tips):  # each on its own flank (poses and contacts in target order)
        d = (tip - floor) / np.linalg.norm(tip - floor)
        rel = p[:2] - floor
        assert abs(rel[0] * d[1] - rel[1] * d[0]) < 1e-3 and 0 < rel @ d < np.linalg.norm(tip - floor)
    assert trimesh.proximity.signed_distance(hull, cs.points).min() > 0.005  # > 0 inside the hull


def test_contour_following_lays_a_line_of_contacts_on_a_flat_face():
    """After the poke's touch on the cube's top face the tip slides 3 steps of 3 mm each way: the
    readings give contacts on the tip, every one within 1 mm of the face and placed within the
    hull's 0.5 mm, a few millimetres apart along the surface across at least 5 mm."""
    cube = trimesh.creation.box((0.08, 0.08, 0.08))
    est = trimesh.creation.box((0.1, 0.1, 0.1))
    (pose,) = poke_poses([[0.005, -0.01, 0.05]], [[0.0, 0.0, 1.0]], [0.03], est, np.zeros(3), 0.09, SPEC)
    band = cached_band(SPEC, ControlConfig(), SimConfig(), SensorConfig(), False)
    with ArmSimulation(SPEC, cube.vertices, cube.faces, SimConfig()) as world:
        robot = world.robot(SensorConfig())
        robot.reseed((0, 0))
        att = run_poke(robot, pose.T_world_base, pose.q0, pose.stop_rad, band, slides=3)
    assert len(att.moments) >= 4 and all(m.still for m in att.moments)
    cs = localise_attempts(SPEC, [att], GRAVITY, SensorConfig())
    assert len(cs) == len(att.moments) and (cs.link == SPEC.n_links - 1).all()
    assert np.abs(cs.points[:, 2] - 0.04).max() < 1e-3
    assert contact_uncertainty_m(cs, cs.sigma_nm).max() <= MAX_UNCERTAINTY_M
    along = np.sort(cs.points @ np.cross(pose.normal, [0.0, 0.0, 1.0]))  # across the face, in the arm's plane
    assert along[-1] - along[0] >= 0.005 and np.diff(along).max() <= 0.004


def test_probe_config_rejects_negative_pokes_and_slides_without_pokes():
    with pytest.raises(ValueError, match="pokes"):
        ProbeConfig(pokes=-1)
    with pytest.raises(ValueError, match="slides"):
        ProbeConfig(pokes=0, slides=2)


def test_pokes_and_their_contours_replay_from_the_logs():
    """A small exploration with a round of pokes that follow the surface, recorded: the loop rerun
    on its logs (no simulator) plans the same pokes and finds the same contacts; read with no
    controller, the pokes' motions are recognised as pokes (they start bent)."""
    from explore3d.robot.interface import LogWorkcell
    from explore3d.strategy.explore import ExploreConfig, explore_robots, rough_bound
    from explore3d.strategy.poke import PokePose
    from explore3d.strategy.readings import exploration_from_readings
    from explore3d.world.explore import explore
    from explore3d.world.objects import cube

    spec = ArmSpec(name="small16", n_links=16, link_length=0.02)
    m = cube()
    cfg = ExploreConfig(directions=8, angles=1, jobs=1, record=True,
                        probes=ProbeConfig(rounds=1, targets=1, orientations=1, across=False, fingers=0, pokes=2,
                                           slides=1))
    ex = explore(m, spec, cfg)
    pokes = [i for i, p in enumerate(ex.poses) if isinstance(p, PokePose)]
    assert pokes and all(ex.attempts[i][0].poke for i in pokes)
    assert any(len(ex.attempts[i][0].moments) > 1 for i in pokes)  # a contour read more than the touch
    c, r = rough_bound(m.vertices)
    again = explore_robots(LogWorkcell(ex.logs), spec, cfg, ex.band, c, r)
    assert [p.label for p in again.poses] == [p.label for p in ex.poses]
    assert np.array_equal(again.contacts.points, ex.contacts.points) and np.array_equal(again.points, ex.points)
    read = exploration_from_readings(ex.logs, spec, cfg, ex.band, c, r)
    assert [a[0].poke for a in read.attempts] == [a[0].poke for a in ex.attempts]


def test_only_poke_contacts_facing_the_centre_are_left_out_of_the_hull():
    """Two wraps, a straight one and a poke, each with a contact whose outward normal points away
    from the centre and one whose normal points at it: only the poke's second is flagged."""
    from explore3d.feeling.contacts import ContactSet
    from explore3d.geometry.directions import WrapPose
    from explore3d.strategy.explore import poke_facing_centre
    from explore3d.strategy.poke import PokePose

    P = np.array([[0.05, 0, 0], [0.05, 0, 0], [0, 0.05, 0], [0, 0.05, 0]], float)
    N = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0]])
    m = len(P)
    cs = ContactSet(points=P, segments=np.stack([P, P], axis=1), normals=N, force_n=np.ones(m),
                    sigma_along_m=np.zeros(m), along_interval_m=np.zeros((m, 2)), link=np.zeros(m, int),
                    wrap=np.array([0, 0, 1, 1]), attempt=np.zeros(m, int), joint=np.zeros(m, int),
                    kind=np.array(["inner"] * m), still=np.ones(m, bool), residual_nm=np.zeros(m),
                    self_contact=np.zeros(m, bool), sigma_nm=np.ones(m))
    wrap = WrapPose(np.eye(4), np.array([0, 0, 1.0]), 0.0, 0.0, "wrap")
    poke = PokePose(np.eye(4), np.array([0, 0, 1.0]), 0.0, 0.0, "poke", q0=np.zeros(3), target=np.zeros(3))
    assert poke_facing_centre(cs, [wrap, poke], np.zeros(3)).tolist() == [False, False, False, True]
    assert not poke_facing_centre(cs, [wrap, wrap], np.zeros(3)).any()
