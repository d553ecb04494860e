"""The arm touching itself: PyBullet's self-collision, the kinematic self-distance
(explore3d.arm.selfcontact) against PyBullet's own geometry, and self-contacts never taken for the
object's (the localisation's flag; the controller's part is in tests/test_encircle.py)."""
import math

import numpy as np
import pytest

from explore3d.arm.spec import ArmSpec
from explore3d.arm.urdf import load_arm
from explore3d.feeling.contacts import contacts_for_hull, localise_attempts
from explore3d.strategy.encircle import Attempt, Moment
from explore3d.strategy.explore import ExploreConfig
from explore3d.feeling.localise import torques_of_contacts
from explore3d.robot.interface import JointReading, make_command
from explore3d.arm.selfcontact import SELF_CONTACT_TOLERANCE_M, near_other_body, point_body_distances, rectangle_distances, self_contact_pairs, self_distances
from explore3d.robot.sensing import SensorConfig
from explore3d.world.sim import ArmSimulation
from explore3d.core.settings import SimConfig

#: Small arms keep these fast; the second has wide links and a large base block.
SMALL = ArmSpec(name="small8", n_links=8, link_length=0.02)
WIDE = ArmSpec(name="wide8", n_links=8, link_length=0.03, link_width=0.012, base_size=0.03)


def _square(x, y, side=1.0):
    return np.array([[x, y], [x + side, y], [x + side, y + side], [x, y + side]])


def test_rectangle_distance_known_answers():
    a = _square(0.0, 0.0)
    assert rectangle_distances(a, _square(2.0, 0.0)) == pytest.approx(1.0)  # face to face
    assert rectangle_distances(a, _square(2.0, 2.0)) == pytest.approx(math.sqrt(2.0))  # corner to corner
    assert rectangle_distances(a, _square(1.0, 0.5)) == pytest.approx(0.0)  # touching
    assert rectangle_distances(a, _square(0.75, 0.1)) == pytest.approx(-0.25)  # overlapping by 0.25 along x
    # a diamond whose corner points at a's right face from 0.5 away
    diamond = np.array([[1.5, 0.5], [2.0, 0.0], [2.5, 0.5], [2.0, 1.0]])
    assert rectangle_distances(a, diamond) == pytest.approx(0.5)
    assert rectangle_distances(diamond, a) == pytest.approx(0.5)


def test_point_distances_and_which_bodies_count_as_another():
    spec = SMALL
    L, w = spec.link_length, spec.link_width
    q = np.zeros(spec.n_links)  # straight along base +x
    D = point_body_distances(spec, q, [[2.5 * L, w / 2 + 0.003, 0.0]])  # 3 mm off link 2's inner face
    assert D[0, 3] == pytest.approx(0.003)  # column i + 1 is link i
    assert D[0, 2] == pytest.approx(math.hypot(0.5 * L, 0.003))
    # the base block's front face stands 1 mm behind joint 0
    assert point_body_distances(spec, q, [[-0.004, 0.0, 0.0]])[0, 0] == pytest.approx(0.0)
    assert point_body_distances(spec, q, [[0.0, 0.0, 0.0]])[0, 0] == pytest.approx(0.001)
    # joint 1's inner corner lies on links 0 and 1: read on link 1, both are itself or its
    # neighbour; read on link 3, links 0 and 1 are other bodies
    corner = [[L, w / 2, 0.0]]
    assert not near_other_body(spec, q, [1], corner)[0]
    assert near_other_body(spec, q, [3], corner)[0]
    # a point 1 mm behind joint 0 is on the base block: link 0's neighbour, link 1's other body
    assert not near_other_body(spec, q, [0], [[-0.001, 0.0, 0.0]])[0]
    assert near_other_body(spec, q, [1], [[-0.001, 0.0, 0.0]])[0]
    with pytest.raises(ValueError, match="links must be in"):
        near_other_body(spec, q, [spec.n_links], corner)


def test_self_contact_pairs_are_the_close_nonadjacent_pairs():
    spec = load_arm("default")
    rng = np.random.default_rng(5)
    for i in range(40):
        q = rng.uniform(spec.joint_lower, spec.joint_upper, spec.n_links) * rng.uniform(0.2, 1.0)
        tol = rng.uniform(0.0, 0.01)
        moving = None if i % 2 else int(rng.integers(0, spec.n_links))
        D = self_distances(spec, q)
        a, b = np.nonzero(np.triu(D <= tol))
        expect = [(int(x) - 1, int(y) - 1) for x, y in zip(a, b) if moving is None or x - 1 < moving <= y - 1]
        assert self_contact_pairs(spec, q, tol, moving) == expect
        assert all(y - x >= 2 for x, y in expect)  # never adjacent bodies
    assert np.isinf(np.diagonal(D, 1)).all()  # adjacent pairs (base-link 0, link i-link i+1) read +inf
    with pytest.raises(ValueError, match="tolerance_m"):
        self_contact_pairs(spec, q, -1.0)
    with pytest.raises(ValueError, match="shape"):
        self_contact_pairs(spec, q[:-1])


def _world_margins(world, n):
    """PyBullet's collision margin of the base (index 0) and of each link, metres."""
    p = world.client
    return np.array([p.getDynamicsInfo(world.arm, j)[-1] for j in range(-1, n)])


@pytest.mark.parametrize("spec", [SMALL, WIDE, load_arm("default")], ids=lambda s: s.name)
def test_self_distance_matches_pybullets_closest_points(spec):
    """On random configurations, every non-adjacent pair: PyBullet's getClosestPoints distance is
    the model's plus 0 to (sqrt(2) - 1)(r_a + r_b), r the two bodies' collision margins (PyBullet
    rounds a box's edges by its margin; the model's boxes are sharp), also when they overlap."""
    rng = np.random.default_rng(11)
    n = spec.n_links
    seen = {"apart": 0, "overlap": 0}
    worst = 0.0
    with ArmSimulation(spec) as world:
        p, arm = world.client, world.arm
        r = _world_margins(world, n)
        assert r.min() > 0
        for it in range(6 if n > 10 else 20):
            q = rng.uniform(spec.joint_lower, spec.joint_upper, n) * (0.5 if it % 2 else 1.0)
            for j in range(n):
                p.resetJointState(arm, j, q[j], 0.0)
            D = self_distances(spec, q)
            for a in range(-1, n):
                for b in range(a + 2, n):
                    far = 0.05
                    cp = p.getClosestPoints(arm, arm, far, a, b)
                    model = D[a + 1, b + 1]
                    bound = (math.sqrt(2.0) - 1.0) * (r[a + 1] + r[b + 1]) + 1e-6
                    if not cp:
                        assert model > far - bound, (a, b, model)
                        continue
                    d = min(c[8] for c in cp)
                    seen["overlap" if d < 0 else "apart"] += 1
                    assert -1e-6 <= d - model <= bound, (a, b, d, model)
                    worst = max(worst, d - model)
    assert seen["apart"] > 10 and seen["overlap"] > 3, seen
    assert worst > 0.2 * bound  # the rounding is really there (the bound is not loose by design)


def _curl_to_limits(spec, self_collision: bool):
    """Drive joints 0 and 1 from straight to their upper limit (2 s, ideal sensing, free space): link
    1 folds back onto the base block.  Returns the final angles and the arm-arm pairs PyBullet
    reports touching."""
    q_goal = np.zeros(spec.n_links)
    q_goal[:2] = spec.joint_upper
    with ArmSimulation(spec, config=SimConfig(self_collision=self_collision)) as world:
        robot = world.robot(SensorConfig.ideal())
        robot.start(np.eye(4), np.zeros(spec.n_links))
        for _ in range(480):
            r = robot.step(make_command(spec, q_goal))
        pairs = {tuple(sorted((c[3], c[4]))) for c in world.client.getContactPoints(world.arm, world.arm)
                 if c[8] < 1e-4}
    return r.q, pairs


def test_self_collision_is_on_by_default_and_stops_links_passing_through():
    """Joints 0 and 1 driven to the upper limit fold link 1 back onto the base block.  With the
    default SimConfig PyBullet reports that pair touching (the base and link 0, joined by joint 0,
    never), the model finds it within its tolerance and joint 1 stops short of its limit; with
    self_collision=False link 1 passes into the block (8 mm deep by the model, no contact)."""
    spec = SMALL
    assert SimConfig().self_collision is True
    q_on, pairs_on = _curl_to_limits(spec, True)
    q_off, pairs_off = _curl_to_limits(spec, False)
    assert pairs_on == {(-1, 1)}, pairs_on
    assert not pairs_off
    assert q_on[1] < spec.joint_upper - 0.3 and q_off[1] > spec.joint_upper - 0.05, (q_on, q_off)
    deepest_on, deepest_off = self_distances(spec, q_on).min(), self_distances(spec, q_off).min()
    assert deepest_off < -0.005 and deepest_on > -0.0005, (deepest_on, deepest_off)
    assert self_contact_pairs(spec, q_on, SELF_CONTACT_TOLERANCE_M) == [(-1, 1)]


def _moment_with_torques(spec, q, tau_ext):
    """A settled reading (planar: gravity along the joint axes) whose external torques are ``tau_ext``."""
    reading = JointReading(t_s=0.0, q=np.asarray(q, float), dq=np.zeros(spec.n_links), tau=-np.asarray(tau_ext, float))
    m = Moment(joint=1, step=1, still=True, reading=reading)
    n = spec.n_links
    return Attempt(T_world_base=np.eye(4), q=reading.q, q_ref=reading.q, contact=np.zeros(n, bool), reasons=(),
                   detect_step=np.zeros(n, int), steps=1, moments=(m,))


def test_a_contact_on_the_base_block_is_a_self_contact_and_never_hulled():
    """Link 1 curled back onto the base block (geometry from the model: joint 1 turned until the
    two meet), pressed by the block's face: the localiser finds a contact on link 1 there (a
    force on the base block reaches no joint, so it reads like an object's) and marks it as the
    arm touching itself; the same force on link 5, far from every other body, is the object's."""
    spec = SMALL
    q = np.zeros(spec.n_links)
    q[0] = 1.9
    lo, hi = 0.5, 2.0  # bisect joint 1 for the model distance link 1 - base block = 0
    for _ in range(60):
        q[1] = 0.5 * (lo + hi)
        lo, hi = (q[1], hi) if self_distances(spec, q)[0, 2] > 0 else (lo, q[1])
    assert abs(self_distances(spec, q)[0, 2]) < 1e-9
    # the block's top back corner touches link 1's inner face; the block pushes the link off
    b = spec.base_size
    corner = np.array([-b - 0.001, b / 2, 0.0])
    assert point_body_distances(spec, q, [corner])[0, 2] < 1e-9
    from explore3d.arm.kinematics import link_transforms

    T1 = link_transforms(spec, q)[1]
    p_link = (np.linalg.inv(T1) @ np.append(corner, 1.0))[:3]
    assert p_link[1] == pytest.approx(spec.link_width / 2) and 0 < p_link[0] < spec.link_length
    f_link = np.array([0.0, -2.0, 0.0])  # 2 N along the inner face's inward normal
    tau = torques_of_contacts(spec, q, [(1, p_link, f_link)])
    atts = [_moment_with_torques(spec, q, tau)]
    cs = localise_attempts(spec, atts, np.array([0.0, 0.0, -9.81]), SensorConfig.ideal())
    assert len(cs) == 1 and cs.link[0] == 1
    # a face force and a corner force fit the two loaded joints alike: the touching point lies in
    # the contact's profile interval, wherever the located point is
    lo, hi = cs.along_interval_m[0]
    assert lo - 1e-4 <= p_link[0] <= hi + 1e-4, (lo, p_link[0], hi)
    assert cs.self_contact.tolist() == [True]
    hulled = contacts_for_hull(cs, ExploreConfig(mode="planar", sensors=SensorConfig.ideal()), np.zeros(3), 0.3)
    assert not hulled.used.any()
    # the same force on link 5's inner face: not near another body
    T5 = link_transforms(spec, q)[5]
    tau5 = torques_of_contacts(spec, q, [(5, np.array([0.01, spec.link_width / 2, 0.0]), np.array([0.0, -2.0, 0.0]))])
    cs5 = localise_attempts(spec, [_moment_with_torques(spec, q, tau5)], np.array([0.0, 0.0, -9.81]),
                            SensorConfig.ideal())
    assert cs5.link.tolist() == [5] and cs5.self_contact.tolist() == [False]
    assert contacts_for_hull(cs5, ExploreConfig(mode="planar", sensors=SensorConfig.ideal()), T5[:3, 3], 0.3).used.all()


def test_band_calibration_learns_no_signal_of_the_arm_touching_itself(monkeypatch):
    """The impact wraps of the calibration curl the 16-link arm round the known block until it
    touches itself (PyBullet reports arm-arm contacts); no step at which it does feeds a band."""
    from explore3d.world import band as band_mod
    from explore3d.world import sim as sim_mod

    spec = ArmSpec(name="small16", n_links=16, link_length=0.02)
    worlds = []
    init = sim_mod.ArmSimulation.__init__

    def keep(self, *a, **k):
        init(self, *a, **k)
        worlds.append(self)

    monkeypatch.setattr(sim_mod.ArmSimulation, "__init__", keep)
    recorded = {"steps": 0, "touching_itself": 0, "seen_touching": 0}
    add = band_mod._Maxima.add

    def checked_add(self, k, lag, sig):
        w = worlds[-1]
        recorded["steps"] += 1
        recorded["touching_itself"] += any(c[8] < 1e-4 for c in w.client.getContactPoints(w.arm, w.arm))
        add(self, k, lag, sig)

    monkeypatch.setattr(band_mod._Maxima, "add", checked_add)
    # count the steps at which the arm touches itself at all (observer calls see every sweep step)
    exceeds = band_mod.SweepDetector.exceeds

    def watching_exceeds(band, k, lag, sig):
        w = worlds[-1]
        recorded["seen_touching"] += any(c[8] < 1e-4 for c in w.client.getContactPoints(w.arm, w.arm))
        return exceeds(band, k, lag, sig)

    monkeypatch.setattr(band_mod.SweepDetector, "exceeds", staticmethod(watching_exceeds))
    b = band_mod.calibrate_band(spec, planar=True)
    assert recorded["steps"] > 1000 and recorded["touching_itself"] == 0, recorded
    assert recorded["seen_touching"] > 0, recorded  # the arm did touch itself in the calibration
    assert sum(p["self_contacts"] for p in b.provenance["impact_passes"]) > 0
