"""Contacts localised from simulated readings with known answers (explore3d.feeling.contacts).

A small fixed sphere is placed where a known link of the default arm will touch it; the arm runs
one attempt through the robot interface with the default sensing; the settled reading of the
first detection is localised from the joint angles and motor torques alone and compared with the
geometric truth (the point of the link's inner face nearest the sphere's centre, from the arm's
own kinematics at that reading).  The two-contact and corner cases are also covered with exact
torques in tests/test_localise.py.
"""
import numpy as np
import pytest
import trimesh

from explore3d import ExploreConfig, load_arm
from explore3d.world.band import cached_band
from explore3d.feeling.contacts import ContactSet, contact_uncertainty_m, contacts_for_hull, localise_attempts, localise_moment, resolve_heights, torque_sigma_nm
from explore3d.strategy.encircle import ControlConfig, Controller, run_attempt
from explore3d.arm.kinematics import link_transforms
from explore3d.robot.sensing import SensorConfig
from explore3d.world.sim import ArmSimulation
from explore3d.core.settings import SimConfig

SPEC = load_arm("default")
R_BALL = 0.005
GRAVITY = np.array([0.0, 0.0, -9.81])


def _first_moment(centre_xy):
    """One planar attempt (base at the origin, joint axes vertical) against a 5 mm sphere at
    ``centre_xy``; returns the attempt and its first settled reading."""
    ball = trimesh.creation.icosphere(subdivisions=3, radius=R_BALL)
    ball.apply_translation([centre_xy[0], centre_xy[1], 0.0])
    band = cached_band(SPEC, ControlConfig(), SimConfig(), SensorConfig(), True)
    with ArmSimulation(SPEC, ball.vertices, ball.faces, SimConfig()) as world:
        robot = world.robot(SensorConfig())
        robot.reseed((0, 0))
        att = run_attempt(robot, np.eye(4), band, ControlConfig())
    assert att.moments, "the arm did not detect the ball"
    return att, att.moments[0]


def _truth_on_link(q, link, centre_xy):
    """x along ``link`` (its frame, metres) of the inner-face point nearest the sphere centre."""
    T = link_transforms(SPEC, q)[link]
    p = np.linalg.inv(T) @ np.array([centre_xy[0], centre_xy[1], 0.0, 1.0])
    return float(p[0])


@pytest.mark.parametrize("link", [5, 14])
def test_a_ball_touching_a_known_link_is_found_there(link):
    """The ball sits 10 mm off the inner face at the middle of ``link``: joint 0's sweep brings the
    link onto it; the contact is found on that link, within 1 mm in the plane."""
    L, w = SPEC.link_length, SPEC.link_width
    centre = ((link + 0.5) * L, w / 2 + R_BALL + 0.010)
    att, m = _first_moment(centre)
    assert m.joint == 0
    loc = localise_moment(SPEC, m, np.eye(4), GRAVITY, SensorConfig())
    assert len(loc.contacts) == 1, loc.contacts
    c = loc.contacts[0]
    assert c.link == link
    x_true = _truth_on_link(m.reading.q, link, centre)
    assert abs(c.point_link[0] - x_true) < 1e-3
    assert c.point_link[1] == pytest.approx(w / 2)  # on the inner face
    # in the world: the located point is the ball's surface point towards the link, within 1 mm
    touch = np.array([*centre, 0.0]) + R_BALL * c.normal_world  # the normal points into the link
    assert np.linalg.norm(c.point_world[:2] - touch[:2]) < 1e-3
    assert c.force_n > 0.5 and loc.residual_nm <= 2 * torque_sigma_nm(SensorConfig())


def test_a_ball_ahead_of_the_tip_is_found_on_the_tip_within_its_reported_interval():
    """A ball just ahead of the tip on the curl side meets the tip's inner distal corner.  Pressed
    by joint 0 over the whole arm's 0.48 m lever the force is under 1 N: the position along the
    link is poorly resolved, and the contact says so (its interval holds the corner, its
    uncertainty keeps it out of the hull)."""
    n, L, w = SPEC.n_links, SPEC.link_length, SPEC.link_width
    centre = (n * L + 0.5 * R_BALL, w / 2 + R_BALL + 0.004)
    att, m = _first_moment(centre)
    cs = localise_attempts(SPEC, [att], GRAVITY, SensorConfig())
    first = cs.select(cs.joint == m.joint)
    assert len(first) == 1 and first.link[0] == n - 1
    lo, hi = first.along_interval_m[0]
    assert lo - 1e-9 <= L <= hi + 1e-9  # the corner (x = L) is inside the reported interval
    assert contact_uncertainty_m(first, torque_sigma_nm(SensorConfig()))[0] > 0.5e-3


def test_free_space_readings_give_no_contact():
    """Held still in free space (no object) with tilted bases, so gravity loads the joints and its
    feed-forward cancels: nothing is localised from the settled readings."""
    from scipy.spatial.transform import Rotation

    far = trimesh.creation.box((0.01, 0.01, 0.01))
    far.apply_translation([5.0, 5.0, 5.0])
    for rotvec in ([0.0, 0.0, 0.0], [0.6, 0.3, 0.0], [1.4, -0.4, 0.2]):
        T = np.eye(4)
        T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
        with ArmSimulation(SPEC, far.vertices, far.faces, SimConfig()) as world:
            robot = world.robot(SensorConfig())
            robot.reseed((0, 1))
            ctl = Controller(robot, ControlConfig(), T)
            ctl.start()
            q_ref = np.zeros(SPEC.n_links)
            q_ref[[0, 3, 9]] = (0.5, 0.8, 1.2)  # a bent arm
            still, reading = ctl.settle(q_ref)
            for _ in range(200):
                ctl.send(q_ref)
            from explore3d.strategy.encircle import Moment

            m = Moment(joint=0, step=ctl.steps, still=True, reading=ctl.reading)
            assert localise_moment(SPEC, m, T, GRAVITY, SensorConfig()).contacts == ()


def test_contacts_of_a_wrap_are_deterministic_and_labelled():
    centre = (5.5 * SPEC.link_length, SPEC.link_width / 2 + R_BALL + 0.010)
    att, _ = _first_moment(centre)
    a = localise_attempts(SPEC, [att], GRAVITY, SensorConfig(), wrap=7)
    b = localise_attempts(SPEC, [att], GRAVITY, SensorConfig(), wrap=7)
    assert len(a) >= 1 and np.all(a.wrap == 7) and np.all(a.attempt == 0)
    for f in ContactSet.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    assert set(a.joint.tolist()) <= {m.joint for m in att.moments}
    np.testing.assert_allclose(np.linalg.norm(a.normals, axis=1), 1.0)
    # the point lies on its segment, which spans the link's height along the base z axis
    np.testing.assert_allclose(a.segments.mean(axis=1), a.points, atol=1e-12)
    np.testing.assert_allclose(np.abs(a.segments[:, 1, 2] - a.segments[:, 0, 2]), SPEC.link_height)


def test_uncertainty_is_the_worst_of_resolution_interval_and_fit():
    cs = ContactSet.empty()
    z3 = np.zeros((3, 3))
    cs = ContactSet(points=z3, segments=np.zeros((3, 2, 3)), normals=z3, force_n=np.array([10.0, 0.5, 10.0]),
                    sigma_along_m=np.array([1e-5, 1e-5, 2e-3]), along_interval_m=np.array([[0.01, 0.0102],
                                                                                            [0.0, 0.0],
                                                                                            [np.nan, np.nan]]),
                    link=np.zeros(3, int), wrap=np.zeros(3, int), attempt=np.zeros(3, int), joint=np.zeros(3, int),
                    kind=np.array(["inner", "inner", "distal"]), still=np.ones(3, bool))
    u = contact_uncertainty_m(cs, 1e-3)
    np.testing.assert_allclose(u[:2], [2e-4, 2e-3])  # the interval width; sigma / force
    assert u[2] == np.inf  # no profile interval


def test_resolve_heights_finds_the_touching_end_on_a_known_box():
    """Segments standing on a 40 mm cube's faces at a tilt: each touches the cube at one end (the
    other sticks out).  Judged by the other planes, the chosen points come out at the touching
    ends; the mid-height points lie millimetres off."""
    rng = np.random.default_rng(0)
    cube = trimesh.creation.box((0.04, 0.04, 0.04))
    segs, wraps = [], []
    for k in range(400):
        face = rng.integers(6)
        axis, sign = face // 2, 1.0 if face % 2 else -1.0
        p = rng.uniform(-0.018, 0.018, 3)
        p[axis] = sign * 0.02  # on the face
        n = np.zeros(3)
        n[axis] = sign
        tilt = rng.normal(size=3)
        tilt -= (tilt @ n) * n
        tilt /= np.linalg.norm(tilt)
        ang = rng.uniform(0.2, 0.6)
        d = np.cos(ang) * tilt + np.sin(ang) * n  # leaves the face outward
        segs.append([p, p + 0.01 * d])
        wraps.append(k % 40)
    S, W = np.array(segs), np.array(wraps)
    P = resolve_heights(S, W, np.zeros(3), 0.04, group=W)
    d_chosen = np.abs(trimesh.proximity.signed_distance(cube, P))
    d_mid = np.abs(trimesh.proximity.signed_distance(cube, S.mean(axis=1)))
    assert np.median(d_chosen) < 0.3e-3 < 1.5e-3 < np.median(d_mid)


def test_contacts_for_hull_keeps_what_is_certain():
    att, _ = _first_moment((5.5 * SPEC.link_length, SPEC.link_width / 2 + R_BALL + 0.010))
    cs = localise_attempts(SPEC, [att], GRAVITY, SensorConfig())
    cfg = ExploreConfig(mode="planar")
    out = contacts_for_hull(cs, cfg, np.zeros(3), 0.3)
    sigma = torque_sigma_nm(cfg.sensors)
    expect = (contact_uncertainty_m(cs, sigma) <= 0.5e-3) & (cs.residual_nm <= 2 * sigma) & cs.still & ~cs.self_contact
    np.testing.assert_array_equal(out.used, expect)
    np.testing.assert_array_equal(out.points, cs.points)  # planar: no height to resolve
