"""Planar rigid registration of a moved object's contacts (explore3d.reconstruction.registration)
and carrying an exploration's later epochs back (explore3d.strategy.motion.carry_back)."""
import dataclasses
import math

import numpy as np
import pytest
import trimesh

from explore3d.arm.urdf import load_arm
from explore3d.reconstruction.registration import planar_transform, register_on_table
from explore3d.strategy.explore import Exploration, ExploreConfig
from explore3d.strategy.motion import carry_back, motion_trust, wrap_epochs

BOX = trimesh.creation.box((0.08, 0.08, 0.08))


def _band_points(rng, n_per_face=8, faces=((0, 1), (0, -1), (1, 1), (1, -1)), z=(-0.03, 0.03), half=0.035):
    """Points on the box's vertical faces in a horizontal band: what horizontal wraps touch."""
    out = []
    for ax, sign in faces:
        for _ in range(n_per_face):
            p = rng.uniform(-half, half, 3)
            p[ax] = 0.04 * sign
            p[2] = rng.uniform(*z)
            out.append(p)
    return np.array(out)


def _apply(T, P):
    return P @ T[:3, :3].T + T[:3, 3]


@pytest.mark.parametrize("dx,dy,yaw_deg", [(0.005, -0.003, 4.0), (-0.008, 0.002, -7.0), (0.0, 0.0, 10.0)])
def test_known_displacement_recovered_within_1mm(dx, dy, yaw_deg):
    rng = np.random.default_rng(1)
    P = _band_points(rng)
    moved = _apply(planar_transform(dx, dy, math.radians(yaw_deg), (0.01, -0.02, 0.0)), P)
    reg = register_on_table(moved, BOX)
    back = _apply(reg.T, moved)
    assert reg.observable
    assert np.linalg.norm(back - P, axis=1).max() < 1e-3
    assert reg.rms_m < 1e-4 < reg.rms_before_m
    assert abs(math.degrees(reg.yaw_rad) + yaw_deg) < 0.5  # the motion undone


def test_invariant_under_a_rigid_motion_of_the_whole_scene():
    """The same displacement, with the box and the points turned about the vertical and slid: the
    points come back onto the box just as well."""
    rng = np.random.default_rng(2)
    P = _band_points(rng)
    M = planar_transform(0.3, -0.1, math.radians(33.0))
    box = BOX.copy()
    box.apply_transform(M)
    D = planar_transform(0.004, 0.006, math.radians(-5.0), (0.0, 0.0, 0.0))
    moved = _apply(M @ D, P)
    reg = register_on_table(moved, box)
    assert np.linalg.norm(_apply(reg.T, moved) - _apply(M, P), axis=1).max() < 1e-3


def test_one_face_does_not_fix_the_motion():
    rng = np.random.default_rng(3)
    P = _band_points(rng, faces=((0, 1),))
    reg = register_on_table(_apply(planar_transform(0.0, 0.004, 0.0), P), BOX)
    assert not reg.observable


def test_bad_points_are_refused():
    with pytest.raises(ValueError, match="at least 3 finite points"):
        register_on_table(np.zeros((2, 3)), BOX)
    with pytest.raises(ValueError, match="at least 3 finite points"):
        register_on_table(np.full((5, 3), np.nan), BOX)


def test_wrap_epochs():
    assert wrap_epochs([False, False, True, False, True, False]).tolist() == [0, 0, 0, 1, 1, 2]
    assert wrap_epochs([]).tolist() == []


def _exploration(points, wraps, moved):
    n = len(moved)
    z = np.zeros(len(points), int)
    return Exploration(spec=load_arm("default"), config=ExploreConfig(), poses=tuple(range(n)),
                       attempts=tuple(() for _ in range(n)), points=points, point_wrap=np.asarray(wraps),
                       point_attempt=z, point_link=z, band=None, steps=0, sim_time_s=0.0, wall_s=0.0,
                       table_z=-0.04, moved=np.asarray(moved, bool), redone=np.zeros(n, bool))


def test_carry_back_puts_a_moved_epoch_back_on_the_first():
    """Wraps 0-1 touch the box where it rested, wrap 2 pushed it (flagged: its points mix two
    poses), wraps 3-4 touch it 6 mm and 5 degrees away: carried back within 1 mm of the box."""
    rng = np.random.default_rng(4)
    first = np.vstack([_band_points(rng, 30, z=(-0.04, 0.0), half=0.04), _band_points(rng, 30, z=(0.0, 0.04), half=0.04)])
    top = np.c_[rng.uniform(-0.04, 0.04, (30, 2)), np.full(30, 0.04)]
    first = np.vstack([first, top])
    D = planar_transform(0.006, -0.002, math.radians(5.0), (0.0, 0.0, 0.0))
    truth_later = _band_points(rng)
    later = _apply(D, truth_later)
    junk = rng.uniform(-0.05, 0.05, (6, 3))
    pts = np.vstack([first, junk, later])
    wraps = np.r_[np.repeat([0, 1], [120, len(first) - 120]), np.full(6, 2), np.repeat([3, 4], [16, 16])]
    ex = _exploration(pts, wraps, [False, False, True, False, False])
    out = carry_back(ex, np.zeros(3), 0.075)
    assert [r["action"] for r in out.registrations] == ["registered"]
    assert 2 not in set(out.point_wrap.tolist())  # the flagged wrap's points dropped
    back = out.points[out.point_wrap >= 3]
    err = np.linalg.norm(back - truth_later, axis=1)
    assert err.max() < 1e-3  # the displacement recovered (7 mm at the points before)
    assert len(out.points) == len(first) + len(later)


def test_carry_back_leaves_an_unmoved_exploration_alone():
    rng = np.random.default_rng(5)
    P = _band_points(rng)
    ex = _exploration(P, np.zeros(len(P), int), [False])
    assert carry_back(ex, np.zeros(3), 0.075) is ex


def test_carry_back_keeps_an_epoch_when_there_is_no_estimate_to_register_to():
    """The first epoch's points all on one side of the rough centre: no inverse hull about it;
    the later points are kept where they were touched (as without carrying back), not lost."""
    rng = np.random.default_rng(6)
    first = _band_points(rng, 40, faces=((0, 1),))  # one face only: the centre is outside their hull
    later = _band_points(rng, 8)
    pts = np.vstack([first, later])
    wraps = np.r_[np.zeros(len(first), int), np.full(len(later), 2)]
    out = carry_back(_exploration(pts, wraps, [False, True, False]), np.zeros(3), 0.075)
    assert [r["action"] for r in out.registrations] == ["kept"] and "no estimate" in out.registrations[0]["reason"]
    assert np.array_equal(out.points[out.point_wrap == 2], later)


def test_motion_trust_says_which_points_agree():
    """The robot's own verdict on the estimate: no flag, all points agree; a flagged wrap whose later
    epoch was carried back, every kept point agrees; the same epoch left where it was touched, only
    the first epoch's points do, and the flagged wrap's own points are counted in no epoch."""
    wraps = np.r_[np.zeros(50, int), np.ones(30, int), np.full(6, 2), np.full(20, 3)]
    none = motion_trust([False] * 4, wraps)
    assert none["verdict"] == "no motion noticed" and none["consistent_fraction"] == 1.0
    assert none["points_by_epoch"] == [len(wraps)]
    mixed = motion_trust([False, False, True, False], wraps)
    assert mixed["verdict"] == "mixed poses" and mixed["wraps_flagged"] == [2]
    assert mixed["points_by_epoch"] == [80, 20] and mixed["points_flagged_wraps"] == 6
    assert mixed["consistent_fraction"] == 80 / len(wraps) and "75%" in mixed["note"]
    kept = wraps[wraps != 2]  # carry_back drops the flagged wrap's points
    back = motion_trust([False, False, True, False], kept, [{"epoch": 1, "action": "registered"}])
    assert back["verdict"] == "carried back" and back["consistent_fraction"] == 1.0
    lost = motion_trust([False, False, True, False], kept, [{"epoch": 1, "action": "dropped"}])
    assert lost["verdict"] == "mixed poses" and lost["consistent_fraction"] == 80 / 100


def test_carried_back_exploration_reports_its_motion():
    """exploration_summary of a persistent world's exploration carries the robot's verdict (the
    carry_back fixture: wrap 2 flagged, wraps 3-4 registered back)."""
    from explore3d.app.pipeline import exploration_summary
    from explore3d.core.settings import SceneConfig
    rng = np.random.default_rng(4)
    first = _band_points(rng, 30, z=(-0.04, 0.04), half=0.04)
    P = np.vstack([first, _band_points(rng)])
    wraps = np.r_[np.zeros(len(first), int), np.full(len(P) - len(first), 2)]
    ex = _exploration(P, wraps, [False, True, False])
    assert "object_motion" not in exploration_summary(ex)  # the ideal scene: a world reset every wrap
    ex = dataclasses.replace(ex, config=dataclasses.replace(ex.config, scene=SceneConfig.named("table")))
    om = exploration_summary(ex)["object_motion"]
    assert om["wraps_flagged"] == [1] and om["verdict"] == "mixed poses"
    assert om["points_by_epoch"] == [len(first), len(P) - len(first)]
