"""Whole-arm encirclement in PyBullet: oracle-free, deterministic, and the paper's findings."""
import numpy as np
import pytest
import trimesh

from explore3d.arm.spec import ArmSpec
from explore3d.world.band import cached_band
from explore3d.strategy.encircle import ControlConfig, StopReason, run_wrap
from explore3d.strategy.explore import ExploreConfig, rough_bound
from explore3d.world.explore import explore
from explore3d.world.objects import cube, square
from explore3d.app.pipeline import reconstruct_exploration
from explore3d.feeling.contacts import localise_attempts
from explore3d.robot.interface import ForwardingRobot
from explore3d.robot.sensing import SensorConfig
from explore3d.world.sim import ArmSimulation

#: A small arm (16 x 20 mm) keeps these tests fast; full-size runs live in scripts/ and BENCHMARKS.md.
SMALL = ArmSpec(name="small16", n_links=16, link_length=0.02)


def _planar(directions, mirrored=False, attempts=2, jobs=1, arm=SMALL, points="links"):
    """A planar exploration of the cube; the paper's findings are about its link points."""
    return explore(cube(), arm, ExploreConfig(mode="planar", directions=directions, mirrored=mirrored,
                                              attempts=attempts, jobs=jobs, points=points))


def _area_err(ex, a=0.05):
    c, R = rough_bound(cube().vertices)
    poly = reconstruct_exploration(ex, c, R, a=a).polygon
    truth = square()
    return (poly.area + truth.area - 2 * poly.intersection(truth).area) / truth.area


def test_bit_identical_and_independent_of_jobs():
    a = _planar(2, mirrored=True, attempts=2, jobs=1, points="contacts")
    b = _planar(2, mirrored=True, attempts=2, jobs=2, points="contacts")
    for wa, wb in zip(a.attempts, b.attempts):
        for x, y in zip(wa, wb):
            assert np.array_equal(x.q, y.q)
            assert all(np.array_equal(m.reading.tau, n.reading.tau) for m, n in zip(x.moments, y.moments))
    assert len(a.contacts) > 0
    for f in ("points", "segments", "normals", "force_n", "link", "used"):
        assert np.array_equal(getattr(a.contacts, f), getattr(b.contacts, f)), f
    assert np.array_equal(a.points, b.points)


class _SelfTouchWatcher(ForwardingRobot):
    """Passes the simulated arm through; after every step notes the arm-arm pairs PyBullet reports
    touching (evaluation only)."""

    def __init__(self, world):
        super().__init__(world.robot())
        self.world, self.pairs = world, set()

    def on_step(self, command, reading):
        p, arm = self.world.client, self.world.arm
        self.pairs |= {tuple(sorted((c[3], c[4]))) for c in p.getContactPoints(arm, arm) if c[8] < 1e-4}


@pytest.mark.parametrize("action", ["end", "retreat"])
def test_curling_onto_itself_in_free_space_gives_no_contact(action):
    """In free space the chain curls until it touches itself (PyBullet reports arm-arm contacts:
    link 1 folds onto the base block); those sweeps end as self-contacts, never as contacts, and no
    settled reading is taken.  By default the attempt ends at its first self-contact (the joints
    after it are not swept); backing off instead, free joints swing to their limit until the chain
    has curled a full turn, and the rest are not swept."""
    band = cached_band(SMALL, planar=True)
    with ArmSimulation(SMALL) as world:
        robot = _SelfTouchWatcher(world)
        atts = run_wrap(robot, np.eye(4), band, attempts=1, cfg=ControlConfig(self_contact_action=action))
    att = atts[0]
    assert robot.pairs and all(b - a >= 2 for a, b in robot.pairs), robot.pairs
    assert not att.contact.any() and not att.moments
    assert localise_attempts(SMALL, atts, robot.gravity, SensorConfig()).points.shape == (0, 3)
    reasons = att.reasons
    assert StopReason.SELF in reasons
    if action == "end":
        k = reasons.index(StopReason.SELF)
        assert k > 0 and all(r is StopReason.LIMIT for r in reasons[:k])
        assert all(r is StopReason.ENDED for r in reasons[k + 1:])
        return
    k = reasons.index(StopReason.WRAPPED)
    assert k > 0 and all(r in (StopReason.LIMIT, StopReason.SELF) for r in reasons[:k])
    assert all(r is StopReason.WRAPPED for r in reasons[k:])
    assert att.q[:k].sum() >= ControlConfig().max_curl


def test_contact_faces_touch_the_cube():
    """Oracle check after the run: links whose joint detected contact lie close to the surface,
    and nothing penetrates it by more than a millimetre."""
    m = cube()
    ex = _planar(3, attempts=1)
    d = []
    for w in ex.attempts:
        for att in w:
            from explore3d.arm.kinematics import link_surface_points

            P = link_surface_points(SMALL, att.q, att.T_world_base, n_along=5, n_height=1)
            sd = trimesh.proximity.signed_distance(m, P.reshape(-1, 3)).reshape(SMALL.n_links, -1)
            gap = -sd.max(axis=1)  # per link: distance of its closest face point (negative = inside)
            assert gap.min() > -0.001, f"penetration {-gap.min():.4f} m"
            # joint k's contact means something at or beyond link k touches: the nearest such link
            beyond = np.minimum.accumulate(gap[::-1])[::-1]
            d.extend(beyond[att.contact])
    d = np.array(d)
    assert np.median(d) < 0.002, f"median gap behind contact-flagged joints {np.median(d):.4f} m"
    # Measured 2026-11-25: ~10% of detections (the last joints of the chain) have nothing within
    # 5 mm; no bound is asserted on that fraction yet (see BENCHMARKS.md, open problems).


def test_more_directions_are_better():
    """The paper's finding: two directions beat one and three beat two."""
    e1, e2, e3 = (_area_err(_planar(n, mirrored=(n == 2), attempts=4)) for n in (1, 2, 3))
    assert e2 < e1 and e3 < e2, (e1, e2, e3)


def test_many_small_links_beat_four_large():
    small = _area_err(_planar(3, attempts=4), a=0.05)
    large = _area_err(_planar(3, attempts=4, arm="paper"), a=0.05)
    assert small < large, (small, large)


def test_a_wrap_does_not_depend_on_the_wraps_before_it():
    """Each wrap runs in a world of its own: PyBullet's restoreState leaves state behind.  Measured
    with one world per worker: wrap 11 of the default 3D run on the cylinder came out differently
    after wrap 10 than alone, so results depended on the number of jobs.  The same case here."""
    from explore3d.arm.urdf import load_arm
    from explore3d.world.band import cached_band
    from explore3d.strategy.explore import _WORKER, _init_worker, _run_one, wrap_poses
    from explore3d.world.explore import SimWorkcells
    from explore3d.world.objects import cylinder

    m, spec, cfg = cylinder(), load_arm("default"), ExploreConfig()
    c, r = rough_bound(m.vertices)
    poses = wrap_poses(spec, cfg, c, r)
    band = cached_band(spec, cfg.control, cfg.sim, cfg.sensors, False)

    def run(order):
        _init_worker(SimWorkcells(spec, np.asarray(m.vertices, float), np.asarray(m.faces, np.int64), cfg.sim))
        try:
            return {i: _run_one((i, poses[i], band, cfg, (c, r), None))[0] for i in order}
        finally:
            _WORKER.clear()

    alone = run([11])[11]
    after = run([10, 11])[11]
    assert all(np.array_equal(a.q, b.q) and np.array_equal(a.contact, b.contact) for a, b in zip(alone, after))


def test_curl_back_offsets_are_a_hairpin_beyond_the_straight_links():
    import math

    import pytest

    from explore3d.strategy.encircle import CurlBack

    cb = CurlBack(straight_links=2, turn=math.pi, bend=0.45)
    off = cb.offsets(SMALL, ControlConfig(), 3)
    # joints 4, 5 straight (the finger), then the fewest equal outward bends that turn pi, then straight
    m = math.ceil(math.pi / 0.45)
    assert np.all(off[:6] == 0) and np.allclose(off[6:6 + m], -math.pi / m) and np.all(off[6 + m:] == 0)
    assert math.isclose(off.sum(), -math.pi) and off.min() >= SMALL.joint_lower + ControlConfig().limit_margin
    # near the tip the hairpin is cut off by the chain's end
    assert np.all(cb.offsets(SMALL, ControlConfig(), SMALL.n_links - 3) == 0)
    with pytest.raises(ValueError, match="lower joint limit"):
        CurlBack(bend=0.49).offsets(SMALL, ControlConfig(), 0)
    with pytest.raises(ValueError, match="straight_links"):
        CurlBack(straight_links=0)


def test_curl_back_on_a_convex_object_is_no_worse_than_the_straight_sweep():
    """The issue's test.  Measured (12 wraps of the 16-link arm around the 80 mm cube, carved):
    24.5% volume error straight, 11.9% curl-back (35 hulled contacts against 26); the cylinder
    28.5% / 15.5%.  Every curl-back attempt curls after its first contact and keeps the hairpin
    out of the object (the carved free space, from the measured angles, holds no cube)."""
    from explore3d.strategy.encircle import CurlBack
    from explore3d.app.pipeline import run

    errs, runs = {}, {}
    for name, cb in (("straight", None), ("curl-back", CurlBack())):
        res = run(cube(), SMALL, ExploreConfig(directions=12, angles=1, jobs=2, probes=None, curl_back=cb,
                                               record=True))
        errs[name], runs[name] = res.error.percent, res
    assert errs["curl-back"] <= errs["straight"], errs
    ex = runs["curl-back"].exploration
    # the curl happened: after the first detected contact some joint beyond the swept one was bent
    # outward by the hairpin's bend (the straight sweep's references are never below a held
    # joint's re-referenced angle, a few hundredths of a radian)
    curled = [a for w in ex.attempts for a in w if a.contact.any()]
    assert curled and all((a.trajectory_ref < -0.3).any() for a in curled)
    assert not any((a.trajectory_ref < -0.3).any() for w in runs["straight"].exploration.attempts for a in w)
    # within a sweep the joint recorded as swept is the one whose reference rises (between sweeps
    # the hairpin's move changes references beyond it)
    a = curled[0]
    d = np.diff(a.trajectory_ref, axis=0)
    rows = np.flatnonzero((d.max(axis=1) > 0) & (np.diff(a.trajectory_joint) == 0)) + 1
    assert len(rows) > 100 and np.array_equal(np.argmax(d[rows - 1], axis=1), a.trajectory_joint[rows])
