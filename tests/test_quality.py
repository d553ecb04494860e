"""explore3d.world.quality: the oracle measures themselves (known distances, penetrations, sampling
bounds, PyBullet's mesh margin), and the contact quality of real runs of the default arm on the
80 mm cube, with bounds set from measurements (see BENCHMARKS.md, "Contact quality and thickness
calibration")."""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from explore3d.arm.urdf import load_arm
from explore3d.strategy.explore import ExploreConfig
from explore3d.world.explore import explore
from explore3d.arm.kinematics import link_transforms
from explore3d.world.objects import load_object
from explore3d.world.quality import FALSE_DETECTION_TOL_M, contact_gaps, contact_quality, detection_records, sweep_segments, swept_joints
from explore3d.world.replay import replay_wrap
from explore3d.geometry.sdf import BOX_FACES, PYBULLET_MESH_MARGIN_M, SignedDistance, box_min_distance, box_surface_points, face_min_distance

SPEC = load_arm("default")
HALF = 0.04  # half edge of the built-in 80 mm cube, metres


def straight_beside_cube(gap_m: float) -> np.ndarray:
    """(4, 4) base pose putting the straight default arm along +x with its inner face (+y)
    ``gap_m`` outside the cube's face y = -40 mm (negative: inside); links 7..12 overlap the face."""
    T = np.eye(4)
    T[:3, 3] = [-0.2, -HALF - SPEC.link_width / 2 - gap_m, 0.0]
    return T


def sphere_sdf(centre, radius):
    c = np.asarray(centre, float)
    return lambda P: np.linalg.norm(np.asarray(P, float) - c, axis=-1) - radius


def point_box_distance(P, T_world_link):
    """Exact distance (m,) of points P (m, 3) outside the link box with pose T (4, 4)."""
    L, W, H = SPEC.link_length, SPEC.link_width, SPEC.link_height
    local = (np.asarray(P) - T_world_link[:3, 3]) @ T_world_link[:3, :3]
    lo, hi = np.array([0.0, -W / 2, -H / 2]), np.array([L, W / 2, H / 2])
    return np.linalg.norm(np.maximum(0.0, np.maximum(lo - local, local - hi)), axis=-1)


@pytest.fixture(scope="module")
def cube_sdf():
    return SignedDistance(load_object("cube"))


# ---------------------------------------------------------------- the measure itself


def test_box_samples_cover_the_surface_within_the_stated_radius():
    rng = np.random.default_rng(0)
    L, W, H = SPEC.link_length, SPEC.link_width, SPEC.link_height
    for pitch in (5e-3, 2.5e-3, 1e-3):
        pts, face, cover = box_surface_points(SPEC, pitch)
        assert set(np.unique(face)) == set(range(len(BOX_FACES)))
        assert np.allclose(pts[face == 0][:, 1], W / 2) and np.allclose(pts[face == 1][:, 1], -W / 2)
        # random points on random faces are within `cover` of a sample
        u = rng.uniform(size=(2000, 3)) * [L, W, H] + [0, -W / 2, -H / 2]
        axis = rng.integers(0, 3, 2000)
        side = rng.integers(0, 2, 2000)
        hi, lo = np.array([L, W / 2, H / 2]), np.array([0.0, -W / 2, -H / 2])
        u[np.arange(2000), axis] = np.where(side == 1, hi[axis], lo[axis])
        d = np.linalg.norm(u[:, None, :] - pts[None], axis=-1).min(axis=1)
        assert d.max() <= cover + 1e-12
        assert cover <= pitch / math.sqrt(2) + 1e-12


@pytest.mark.parametrize("backend", [pytest.param("open3d", marks=pytest.mark.needs_open3d), "trimesh"])
def test_signed_distance_positive_outside_and_agrees_across_backends(backend):
    mesh = load_object("cube")
    sdf = SignedDistance(mesh, backend=backend)
    assert sdf.backend == backend
    P = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.0, -0.041, 0.0], [0.03, 0.0, 0.0]])
    assert np.allclose(sdf(P), [-HALF, 0.01, 0.001, -0.01], atol=1e-6)
    rng = np.random.default_rng(1)
    Q = rng.uniform(-0.08, 0.08, (500, 3))
    assert np.allclose(sdf(Q), -trimesh.proximity.signed_distance(mesh, Q), atol=1e-6)


@pytest.mark.parametrize("gap_mm", [2.0, 1.0, 0.3, 0.0])
def test_link_at_known_gap_from_the_cube(cube_sdf, gap_mm):
    g = gap_mm / 1000
    T = link_transforms(SPEC, np.zeros(SPEC.n_links), straight_beside_cube(g))
    dist, err, depth = box_min_distance(SPEC, T, cube_sdf)
    assert np.allclose(dist[8:12], g, atol=2e-6)
    assert np.all(depth < 2e-6)  # float32 rounding of the open3d backend at g = 0
    assert np.all(dist[:6] > g + 0.01) and np.all(dist[13:] > g + 0.01)
    assert np.allclose(face_min_distance(SPEC, T[8:12], cube_sdf, "inner"), g, atol=2e-6)
    assert np.all(face_min_distance(SPEC, T[8:12], cube_sdf, "outer") > g + SPEC.link_width - 1e-6)
    # joints 0..9 flagged: the contact link is one of those on the face; its inner face is at g
    contact = np.zeros((1, SPEC.n_links), bool)
    contact[0, :10] = True
    gaps, rows, links = contact_gaps(SPEC, np.zeros((1, SPEC.n_links)), straight_beside_cube(g), contact, cube_sdf)
    assert np.allclose(gaps, g, atol=2e-6) and np.all(rows == 0)
    assert np.all((links >= 7) & (links <= 12)) and np.all(links >= np.arange(10))


@pytest.mark.parametrize("depth_mm", [0.2, 0.5, 1.5])
def test_known_penetration_of_a_link(cube_sdf, depth_mm):
    p = depth_mm / 1000
    T = link_transforms(SPEC, np.zeros(SPEC.n_links), straight_beside_cube(-p))
    dist, _, depth = box_min_distance(SPEC, T, cube_sdf, cutoff_m=0.0)
    assert np.allclose(depth[8:12], p, atol=2e-6)
    assert np.allclose(dist[8:12], -p, atol=2e-6)
    assert np.all(depth[:6] == 0.0)


def test_box_distance_brackets_the_exact_distance_to_a_ball():
    """Against an analytic ball the exact box distance is |centre - box| - r; the sampled value
    must overestimate it by at most the covering radius, at every level of refinement."""
    rng = np.random.default_rng(2)
    r = 0.03
    sdf = sphere_sdf([0.0, 0.0, 0.0], r)
    with np.errstate(all="raise"):
        for _ in range(10):
            q = rng.uniform(-0.3, 0.6, SPEC.n_links)
            Tb = np.eye(4)
            Tb[:3, 3] = rng.uniform(-0.15, 0.05, 3)
            T = link_transforms(SPEC, q, Tb)
            exact = np.array([point_box_distance(np.zeros((1, 3)), t)[0] for t in T]) - r
            outside = exact > 0  # the formula holds for balls whose centre is outside the box
            for pitches in ((5e-3,), (5e-3, 2.5e-3), (5e-3, 1e-3)):
                dist, err, _ = box_min_distance(SPEC, T, sdf, pitches_m=pitches)
                assert np.all(dist[outside] >= exact[outside] - 1e-12)
                assert np.all(dist[outside] - err[outside] <= exact[outside] + 1e-12)
            # the finest grid is within 0.1 mm of the exact distance for boxes near the ball
            near = outside & (exact < 0.01)
            assert np.all(dist[near] - exact[near] < 1e-4)


@pytest.mark.parametrize("margin", [None, 3e-4, 1e-4])
def test_pybullet_mesh_margin_is_what_the_constant_says(cube_sdf, margin):
    """PyBullet reports a link's distance to the concave mesh as its geometric gap minus the
    mesh's collision margin: the reason touching faces rest that far off the surface.  Its own
    default (``collision_margin=None``) is :data:`PYBULLET_MESH_MARGIN_M`; ``SimConfig.collision_margin``
    sets it (the default 0.3 mm)."""
    from explore3d.world.sim import ArmSimulation
    from explore3d.core.settings import SimConfig

    expected = PYBULLET_MESH_MARGIN_M if margin is None else margin
    mesh = load_object("cube")
    with ArmSimulation(SPEC, mesh.vertices, mesh.faces, SimConfig(collision_margin=margin)) as sim:
        for g in (0.005, 0.002, 0.0005, -0.0005):
            sim.robot().start(straight_beside_cube(g), np.zeros(SPEC.n_links))
            sim.client.performCollisionDetection()
            d = {}
            for c in sim.client.getClosestPoints(sim.arm, sim.object, 0.05):
                d[c[3]] = min(d.get(c[3], np.inf), c[8])
            geometric = box_min_distance(SPEC, link_transforms(SPEC, np.zeros(SPEC.n_links), straight_beside_cube(g)),
                                         cube_sdf)[0]
            for j in range(8, 12):
                assert d[j] == pytest.approx(geometric[j] - expected, abs=1e-6)


def test_swept_joints_from_references():
    n = 4
    R = np.zeros((9, n))
    R[0:3, 0] = [0.1, 0.2, 0.3]            # joint 0 sweeps 3 steps
    R[3:, 0] = 0.29                         # held where it stopped
    R[3:5, 1] = [0.1, 0.2]                  # joint 1 sweeps 2 steps
    R[5:, 1] = 0.21
    R[5:9, 3] = [0.1, 0.2, 0.3, 0.4]        # joint 2 never swept (no rows), joint 3 sweeps 4
    assert swept_joints(R).tolist() == [0, 0, 0, 1, 1, 3, 3, 3, 3]

    class Att:
        trajectory = R
        trajectory_ref = R

    assert sweep_segments(Att) == {0: (0, 2), 1: (3, 4), 3: (5, 8)}


def test_bad_inputs_raise_one_line_errors():
    with pytest.raises(ValueError, match="pitch_m"):
        box_surface_points(SPEC, 0.0)
    with pytest.raises(ValueError, match="backend"):
        SignedDistance(load_object("cube"), backend="bullet")
    with pytest.raises(ValueError, match="face must be one of"):
        face_min_distance(SPEC, np.eye(4)[None], sphere_sdf([0, 0, 0], 0.1), face="side")
    with pytest.raises(ValueError, match="q must"):
        contact_gaps(SPEC, np.zeros((2, 3)), np.eye(4), np.zeros((2, 3), bool), sphere_sdf([0, 0, 0], 0.1))


# ---------------------------------------------------------------- real runs (measured bounds)


@pytest.fixture(scope="module")
def planar_run():
    cube = load_object("cube")
    ex = explore(cube, "default", ExploreConfig(mode="planar", directions=3, attempts=1, record=True))
    return cube, ex, contact_quality(ex, cube)


@pytest.fixture(scope="module")
def spatial_run():
    cube = load_object("cube")
    ex = explore(cube, "default", ExploreConfig(directions=4, offsets=1, angles=1, record=True, probes=None))
    return cube, ex, contact_quality(ex, cube)


def test_quality_needs_recorded_trajectories():
    cube = load_object("cube")
    ex = explore(cube, "default", ExploreConfig(mode="planar", directions=1, attempts=1))
    with pytest.raises(ValueError, match="record=True"):
        contact_quality(ex, cube)


#: Upper bounds per run, set from measurements on 2026-11-25 with the controller of commit 23800cb
#: (gravity compensation, tip-speed-capped sweeps, distal-only joint watch): measured false
#: fraction 0.087 planar / 0.022 3D, held knock-off 0.105 / 0.098 rad, distal knock-off 0.110 /
#: 0.079 rad, longest touch-to-detection delay 1.26 / 1.30 s (a link pivoting on a cube corner).
#: The 3D bounds cover the spread over wrap sets, not one sample: the same 3D runs with 3, 5, 6, 7
#: and 8 plane normals (commit 9cfefab + the 3-ray sign test) gave false fractions 0.000-0.056,
#: held knock-off 0.068-0.156 rad, distal 0.036-0.130 rad; a different floating-point rounding
#: (another CPU) draws another sample from that spread.  Since the arm settles until still after
#: each contact (the localisation's quasi-static readings; 2026-11-26): false fraction 0.076 / 0.054,
#: held knock-off 0.170 / 0.037 rad, distal 0.025 / 0.020 rad, longest delay 1.29 / 1.28 s; the
#: planar held bound went from 0.15 to the 3D runs' 0.2 rad with it (the planar held knock-off
#: rose, the others fell).  With the pressing settle (the swept joint keeps pushing while the arm
#: settles): false fraction 0.162 / 0.022, held knock-off 0.029 / 0.037 rad, distal 0.011 / 0.028
#: rad, longest delay 0.97 / 1.27 s; the planar false-fraction bound went from 0.15 to 0.2 with it
#: (11 of this run's 68 detections are false; BENCHMARKS.md and the issue's closing note).
BOUNDS = {
    "planar_run": dict(false_fraction=0.2, knock_off_held_max_rad=0.2, knock_off_distal_max_rad=0.15),
    "spatial_run": dict(false_fraction=0.08, knock_off_held_max_rad=0.2, knock_off_distal_max_rad=0.2),
}


@pytest.mark.parametrize("run", ["planar_run", "spatial_run"])
def test_contact_quality_of_the_default_arm_on_the_cube(run, request):
    """The contact quality of the default arm (planar 3 directions x 1 attempt; 3D 4 wraps)."""
    _, ex, q = request.getfixturevalue(run)
    assert q.n_detections == ex.n_contacts > 0
    # no link geometry more than 1 mm inside the cube
    assert q.penetration_max_m < 1e-3 and q.penetration_trajectory_max_m < 1e-3
    # touching inner faces sit at about the contact margin (0.3 mm by default; PyBullet's own 1 mm
    # gave medians of 1.00 mm planar, 0.93 mm 3D): measured medians 0.37 mm planar, 0.26 mm 3D
    margin = ex.config.sim.collision_margin
    assert 0.5 * margin < q.gap_true_median_m < margin + 0.2e-3
    assert q.gap_true_p90_m < 2.0e-3
    # false detections are farther than the tolerance by definition; the others within it
    assert q.n_false == 0 or q.false_distance_median_m > FALSE_DETECTION_TOL_M
    assert q.false_fraction < BOUNDS[run]["false_fraction"]
    # the whole arm is never away from the cube at a detection (held links stay in contact)
    assert q.free_space_fraction < 0.05
    # touch-to-detection delay: measured median 0.015 s (0.05 s with the hand-set band of the earlier controller)
    assert q.n_delays > 0 and q.delay_median_s < 0.1 and q.delay_max_s < 2.0
    assert q.knock_off_held_max_rad < BOUNDS[run]["knock_off_held_max_rad"]
    assert q.knock_off_distal_max_rad < BOUNDS[run]["knock_off_distal_max_rad"]


def test_false_detections_are_distal_and_never_touched(planar_run):
    """The first joints always detect a real contact; false detections come later in the wrap,
    and in none of their sweeps did the moving chain come near the cube."""
    cube, ex, q = planar_run
    recs = detection_records(ex, cube)
    assert len(recs) == q.n_detections
    false = [r for r in recs if r.chain_distance_m > FALSE_DETECTION_TOL_M]
    assert len(false) == q.n_false
    first = min(r.joint for r in false)
    assert first >= 5 and all(r.chain_distance_m <= FALSE_DETECTION_TOL_M for r in recs if r.joint < first)
    assert all(r.touch_row < 0 for r in false)


def test_replay_is_identical_and_reproduces_the_detections(planar_run):
    """A replay of a wrap gives the same attempts bit for bit; with its exact pre-sweep errors
    the recomputed detection signal crosses its band at every detection step."""
    cube, ex, _ = planar_run
    rp = replay_wrap(ex, cube, 1)
    assert rp.identical
    recs = detection_records(ex, cube, wraps=[1], replays={1: rp})
    assert recs and all(r.trigger >= 0 and r.trigger_ratio >= 1.0 for r in recs)
    # the log holds the recorded sweep steps plus the settle steps
    assert int((rp.sweep_joint >= 0).sum()) == sum(len(a.trajectory) for a in ex.attempts[1])


def test_signed_distance_sign_is_right_where_a_single_ray_grazes_an_edge():
    """A point 9.8 mm outside the cube's corner that a single-ray inside test (open3d's default)
    read as inside; found on a link box sampled along a 3D wrap.  The analytic box distance is the
    independent reference."""
    P = np.array([[-0.04337428, -0.0485465, -0.04347038]])
    q = np.abs(P) - 0.04
    exact = np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)
    d = SignedDistance(load_object("cube"))(P)
    assert exact[0] > 0.009 and abs(d[0] - exact[0]) < 1e-6
