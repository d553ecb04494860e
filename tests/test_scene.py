"""The table scene: settling, a plan that stays above the table, the estimate on the table, noticing
that the object moved.  Geometry first (pure functions), then short simulated runs."""
import dataclasses
import math

import numpy as np
import pytest
import trimesh

from explore3d.arm.spec import ArmSpec
from explore3d.arm.urdf import load_arm
from explore3d.geometry.directions import table_wrap_poses
from explore3d.strategy.encircle import ControlConfig, run_wrap
from explore3d.strategy.explore import ExploreConfig, wrap_poses
from explore3d.reconstruction.freespace import swept_area
from explore3d.arm.kinematics import link_transforms
from explore3d.strategy.motion import deep_free, moved_after
from explore3d.world.objects import cube
from explore3d.core.settings import SceneConfig
from explore3d.world.scene import pose_drift, scene_explore_config, settle_scene, object_pose
from explore3d.world.sim import ArmSimulation
from explore3d.core.settings import SimConfig
from explore3d.reconstruction.tabletop import cut_at_table, support_points
from explore3d.arm.workspace import base_lowest_z, floor_stop, link_corners, lowest_z, plan_lowest_z, pose_clears

DEFAULT = load_arm("default")


# --- configuration ---------------------------------------------------------------------------------

def test_scene_config_rejects_a_resting_object_without_a_table_and_names_the_fix():
    with pytest.raises(ValueError, match="table=True"):
        SceneConfig(resting=True)
    with pytest.raises(ValueError, match="unknown scene 'desk'"):
        SceneConfig.named("desk")
    with pytest.raises(ValueError, match="density"):
        SceneConfig(density=0.0)
    with pytest.raises(ValueError, match="mode='3d'"):
        ExploreConfig(mode="planar", scene=SceneConfig.named("table"))


def test_the_table_scene_config_states_every_idealisation_it_drops():
    cfg = scene_explore_config("table")
    sc = cfg.scene
    assert sc.table and sc.resting and sc.persistent and sc.friction == 0.5 and sc.density == 500.0
    assert cfg.sim.mass_error == 0.05 and cfg.control.tip_speed == ControlConfig.gentle().tip_speed
    assert cfg.control.ramp_time > ControlConfig.gentle().ramp_time  # lengthened to keep within the force budget
    assert SceneConfig().ideal and not sc.ideal
    assert ExploreConfig().scene == SceneConfig()  # the main command's default stays the ideal scene


# --- the plan stays above the table (pure geometry on the arm's model) ------------------------------

def test_link_corners_are_the_link_boxes_of_the_forward_kinematics():
    rng = np.random.default_rng(3)
    q = rng.uniform(-0.4, 1.5, DEFAULT.n_links)
    T = np.eye(4)
    T[:3, :3] = trimesh.transformations.rotation_matrix(0.7, [1, 2, 0.5])[:3, :3]
    T[:3, 3] = [0.1, -0.2, 0.3]
    C = link_corners(DEFAULT, q, T)
    Tl = link_transforms(DEFAULT, q, T)
    L, W, H = DEFAULT.link_length, DEFAULT.link_width, DEFAULT.link_height
    for i in (0, 7, DEFAULT.n_links - 1):
        local = (np.linalg.inv(Tl[i]) @ np.c_[C[i], np.ones(8)].T).T[:, :3]
        assert np.allclose(np.sort(np.unique(local[:, 0].round(9))), [0, L])
        assert np.allclose(np.abs(local[:, 1]), W / 2) and np.allclose(np.abs(local[:, 2]), H / 2)


def test_floor_stop_is_the_last_angle_above_the_floor():
    T = np.eye(4)  # base frame x along world x, curl about world z... tilt it so curling goes down
    T[:3, :3] = trimesh.transformations.rotation_matrix(math.pi / 2, [1, 0, 0])[:3, :3]  # +y -> +z: curl goes up
    T[:3, :3] = T[:3, :3] @ np.diag([1.0, -1.0, -1.0])  # turned over: the curl goes down
    T[:3, 3] = [0.0, 0.0, 0.30]
    q = np.zeros(DEFAULT.n_links)
    floor = 0.10
    a = floor_stop(DEFAULT, q, 0, T, floor, 2.0, step=0.001)
    assert 0 < a < 2.0
    qa = q.copy()
    qa[0] = a
    assert lowest_z(DEFAULT, qa, T) >= floor
    qa[0] = a + 0.002
    assert lowest_z(DEFAULT, qa, T) < floor
    # nothing carried dips: the stop itself
    assert floor_stop(DEFAULT, q, 0, T, -1.0, 2.0) == 2.0


def test_table_wraps_start_above_the_table_and_include_tilted_ones():
    m = cube()  # 80 mm, centred at the origin
    table_z = float(m.bounds[0, 2])
    cfg = scene_explore_config("table")
    poses = wrap_poses(DEFAULT, cfg, np.zeros(3), 0.0727, table_z)
    floor = cfg.floor_z(table_z)
    assert poses and all(pose_clears(DEFAULT, p.T_world_base, floor) for p in poses)
    assert all(base_lowest_z(DEFAULT, p.T_world_base) >= floor for p in poses)
    normals = np.array([p.normal for p in poses])
    horizontal = np.abs(normals[:, 2]) > 0.999
    assert horizontal.sum() == cfg.table_heights * cfg.table_angles and (~horizontal).sum() > 0
    # all the candidates of table_wrap_poses that do not clear were dropped, and some did not
    every = table_wrap_poses(np.zeros(3), 0.0727, DEFAULT.link_width, table_z, 0.014)
    assert len(every) > len(poses)


def test_no_wrap_plan_passes_below_the_table():
    """The commanded references of real wraps (horizontal and tilted), by the arm's model: every link
    stays above the table, checked from the plan (the references sent), not from PyBullet."""
    from explore3d.world.band import cached_band

    m = cube()
    sc = SceneConfig(table=True)  # a fixed object on the table: the plan is what is checked
    cfg = ExploreConfig(scene=sc, probes=None)
    setup = settle_scene(m, sc, DEFAULT)
    table_z = setup.table_z
    floor = cfg.floor_z(table_z)
    poses = wrap_poses(DEFAULT, cfg, np.zeros(3), 0.0727, table_z)
    tilted = [p for p in poses if abs(p.normal[2]) < 0.9]
    # the tilted poses whose straight arm, swept about the base joint, would dip below the table most
    Q = np.zeros((41, DEFAULT.n_links))
    Q[:, 0] = np.linspace(0.0, DEFAULT.joint_upper, 41)
    worst = sorted(tilted, key=lambda p: lowest_z(DEFAULT, Q, p.T_world_base).min())[:3]
    band = cached_band(DEFAULT, cfg.control, cfg.sim, cfg.sensors)
    lowest = []
    with ArmSimulation(DEFAULT, config=cfg.sim, scene=setup) as world:
        robot = world.robot()
        for p in [poses[0]] + worst:
            atts = run_wrap(robot, p.T_world_base, band, attempts=1, record=True, floor_z=floor)
            lowest.append(plan_lowest_z(DEFAULT, atts[0].trajectory_ref, p.T_world_base))
        # the same wrap without the floor: its plan goes below the table (the floor did the work)
        unguarded = run_wrap(robot, worst[0].T_world_base, band, attempts=1, record=True)
    assert min(lowest) >= table_z + sc.table_clearance - 1e-9
    assert plan_lowest_z(DEFAULT, unguarded[0].trajectory_ref, worst[0].T_world_base) < table_z


# --- the estimate on the table ---------------------------------------------------------------------

def test_support_points_and_the_cut_close_a_prism_on_the_table():
    box = trimesh.creation.box([0.08, 0.06, 0.05])  # z from -0.025 to 0.025
    table_z = -0.025
    ring = np.array([[x, y, -0.01] for x in (-0.04, 0.04) for y in (-0.03, 0.03)])
    sp = support_points(np.vstack([ring, ring + [0, 0, 0.02]]), table_z, 0.005)
    assert np.allclose(np.sort(sp[:, :2], axis=0), np.sort(ring[:, :2], axis=0)) and np.allclose(sp[:, 2], table_z)
    tall = trimesh.creation.box([0.08, 0.06, 0.09])  # reaches 0.02 below the table
    cut = cut_at_table(tall, table_z)
    assert cut.is_watertight and cut.bounds[0, 2] == pytest.approx(table_z)
    assert cut.volume == pytest.approx(0.08 * 0.06 * (0.045 - table_z), rel=1e-9)
    assert cut_at_table(box, table_z - 0.001) is box


# --- the world ---------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def settled_cube():
    return settle_scene(cube(), SceneConfig.named("table"), DEFAULT)


def test_the_object_settles_on_the_table_and_stays_put_untouched(settled_cube):
    s = settled_cube
    assert s.mass_kg == pytest.approx(500.0 * cube().volume)
    assert s.truth.volume == pytest.approx(cube().volume, rel=1e-9)
    assert abs(s.truth.bounds[0, 2] - s.table_z) < 1e-3  # it stands on the table (PyBullet's margin)
    with ArmSimulation(DEFAULT, config=SimConfig(), scene=s) as world:
        for _ in range(1200):  # 5 s, the arm away
            world.step_passive()
        d, r = pose_drift(s.T_object, object_pose(world))
    assert d < 1e-3 and r < math.radians(0.5)


def test_the_world_arm_differs_from_the_model_by_the_stated_mass_error():
    with ArmSimulation(DEFAULT, config=SimConfig(mass_error=0.05, mass_seed=2)) as world:
        m = np.array([world.client.getDynamicsInfo(world.arm, j)[0] for j in range(DEFAULT.n_links)])
    ratio = m / DEFAULT.link_mass
    assert np.all(np.abs(ratio - 1) <= 0.05 + 1e-12) and np.ptp(ratio) > 0.02
    with ArmSimulation(DEFAULT, config=SimConfig()) as world:
        m0 = np.array([world.client.getDynamicsInfo(world.arm, j)[0] for j in range(DEFAULT.n_links)])
    assert np.allclose(m0, DEFAULT.link_mass)


def test_link_friction_reaches_the_links():
    """PyBullet drops a whole changeDynamics call on a multibody link that carries collisionMargin."""
    with ArmSimulation(DEFAULT, config=SimConfig(friction=0.3)) as world:
        f = [world.client.getDynamicsInfo(world.arm, j)[1] for j in (-1, 0, DEFAULT.n_links - 1)]
    assert f == pytest.approx([0.3, 0.3, 0.3])


# --- noticing motion -----------------------------------------------------------------------------------

def _area(T, q, spec=DEFAULT):
    return swept_area(spec, np.asarray(q)[None, :], T, np.zeros(3), 0.3)


def test_deep_free_needs_the_margin_all_round():
    T = np.eye(4)
    T[:3, 3] = [-0.05, 0.0, 0.0]
    area = _area(T, np.zeros(DEFAULT.n_links))  # the straight arm along world x at y = 0
    mid = np.array([[0.1, 0.0, 0.0]])
    assert deep_free([area], mid, 0.001).all()  # 1 mm inside across the 8 mm link
    assert not deep_free([area], mid, 0.006).any()  # not 6 mm: the link is 8 mm wide
    assert not deep_free([area], mid + [0, 0, 0.01], 0.001).any()  # outside the slab


def test_moved_after_counts_contact_segments_that_swept_space_contradicts():
    T = np.eye(4)
    T[:3, 3] = [-0.05, 0.0, 0.0]
    area = _area(T, np.zeros(DEFAULT.n_links))  # the straight arm along world x at y = 0, 8 mm wide
    on_arm = np.array([[x, 0.0, 0.0] for x in np.arange(0.05, 0.15, 0.002)])  # its mid-line
    beside = on_arm + [0, 0.02, 0]  # 20 mm to the side: never swept
    partly = np.vstack([on_arm, beside[:3]])
    # an earlier contact segment wholly inside a later wrap's swept space: the object went away
    assert moved_after([[on_arm], []], [[], [area]], 1) == 1
    # a later contact segment wholly inside an earlier wrap's swept space: the object came there
    assert moved_after([[], [on_arm, on_arm]], [[area], []], 1) == 2
    # a segment the sweep does not cover everywhere may still hold the contact
    assert moved_after([[partly, beside], []], [[], [area]], 1) == 0


SMALL = ArmSpec(name="small12", n_links=12, link_length=0.025)


def _small_table_run(density):
    from explore3d.world.explore import explore
    from explore3d.world.scene import SceneWatch

    cfg = scene_explore_config("table", spec=SMALL, table_heights=1, table_angles=6, directions=1)
    cfg = dataclasses.replace(cfg, scene=dataclasses.replace(cfg.scene, density=density))
    m = cube(0.04)
    setup = settle_scene(m, cfg.scene, SMALL, cfg.sim)
    watch = SceneWatch(setup)
    ex = explore(m, SMALL, cfg, setup=setup, after_wrap=watch.after_wrap)
    return ex, watch.summary(ex)


def test_a_light_object_pushed_away_is_noticed_and_a_heavy_one_is_not():
    light, ls = _small_table_run(100.0)  # 6.4 g: the gentle sweeps still shove it
    heavy, hs = _small_table_run(20000.0)  # 1.28 kg: stays
    assert ls["max_drift_m"] > 0.02 and light.moved.any()
    # a flagged wrap is repeated once, from the same pose
    i = int(np.nonzero(light.redone)[0][0])
    assert light.moved[i - 1] and np.array_equal(light.poses[i].T_world_base, light.poses[i - 1].T_world_base)
    assert hs["max_drift_m"] < 1e-3 and not heavy.moved.any() and not heavy.redone.any()
    assert len(hs["drift_after_wrap_m"]) == heavy.n_wraps


def test_top_search_halves_the_heights_between_the_highest_touch_and_the_lowest_miss():
    from explore3d.strategy.explore import top_search_height

    assert top_search_height([0.01, 0.03, 0.05], [True, True, False], 0.002) == pytest.approx(0.04)
    # order does not matter; a miss below the highest touch (a wrap that missed a narrow part) is ignored
    assert top_search_height([0.05, 0.01, 0.03], [False, False, True], 0.002) == pytest.approx(0.04)
    assert top_search_height([0.01, 0.03], [False, False], 0.002) is None  # nothing touched
    assert top_search_height([0.01, 0.03], [True, True], 0.002) is None  # the top is above the range
    assert top_search_height([0.030, 0.0315], [True, False], 0.002) is None  # found to the tolerance
    with pytest.raises(ValueError, match="same length"):
        top_search_height([0.01, 0.03], [True], 0.002)


@pytest.mark.parametrize("top", [0.0112, 0.0333, 0.0519])
def test_top_search_brackets_a_known_top_to_the_tolerance_in_log2_steps(top):
    """A slab of half-height h touches when its bottom is below the top: the search's interval
    always holds ``top + h`` and shrinks to the tolerance in ceil(log2(spacing / tol)) wraps."""
    from explore3d.strategy.explore import top_search_height

    h, tol = 0.005, 0.002
    heights = list(np.linspace(0.004, 0.064, 5))
    touched = [z - h < top for z in heights]
    spacing = heights[1] - heights[0]
    for _ in range(int(np.ceil(np.log2(spacing / tol)))):
        z = top_search_height(heights, touched, tol)
        assert z is not None
        heights.append(z)
        touched.append(z - h < top)
    assert top_search_height(heights, touched, tol) is None
    lo = max(z for z, t in zip(heights, touched) if t)
    hi = min(z for z, t in zip(heights, touched) if not t and z > lo)
    assert lo <= top + h < hi and hi - lo <= tol


def test_top_search_wraps_are_horizontal_at_the_height_asked_and_clear_the_table():
    from explore3d.arm.urdf import load_arm
    from explore3d.arm.workspace import pose_clears
    from explore3d.geometry.directions import horizontal_wrap_pose

    spec = load_arm("default")
    p = horizontal_wrap_pose(np.zeros(3), 0.07, spec.link_width, -0.04, 0.021, 0.3, up=False, label="top search")
    assert p.T_world_base[2, 3] == pytest.approx(0.021) and p.normal[2] == -1.0
    assert p.label == "top search z+61mm a17deg cw" and pose_clears(spec, p.T_world_base, -0.04 + 0.002)
    with pytest.raises(ValueError, match="table_top_tol_m"):
        from explore3d.strategy.explore import ExploreConfig
        ExploreConfig(table_top_tol_m=0.0)


def _one_wrap_on_the_table(mesh, mass_kg):
    """One horizontal wrap (and the top search's one) of the small arm around ``mesh`` of ``mass_kg``
    resting on the table, the table scene's default detector: (exploration, SceneWatch summary)."""
    from explore3d.world.explore import explore
    from explore3d.world.scene import SceneWatch

    cfg = scene_explore_config("table", spec=SMALL, table_heights=1, table_angles=1, directions=1, table_top_wraps=1)
    cfg = dataclasses.replace(cfg, scene=dataclasses.replace(cfg.scene, density=mass_kg / mesh.volume))
    setup = settle_scene(mesh, cfg.scene, SMALL, cfg.sim)
    assert setup.mass_kg == pytest.approx(mass_kg)
    watch = SceneWatch(setup)
    ex = explore(mesh, SMALL, cfg, setup=setup, after_wrap=watch.after_wrap)
    return ex, watch.summary(ex)


def test_one_wrap_around_a_tenth_of_a_kilo_cube_on_the_table_moves_it_under_2mm():
    """Issue 40's test: the torque detector stops each sweep at the first touch anywhere on the
    chain and holds; the 40 mm, 0.1 kg cube stays within 2 mm and 2 degrees (measured 0.03 mm,
    0.36 deg), every detection a true touch, each touch's force recorded."""
    ex, s = _one_wrap_on_the_table(cube(0.04), 0.1)
    assert ex.config.control.detector == "torque" and not ex.config.control.press_while_settling
    assert ex.n_contacts > 0 and s["false_detections"] == 0
    assert s["max_drift_m"] < 2e-3 and s["drift_deg"] < 2.0
    f = s["touch_force_n"]
    assert f["touches"] == s["detections_watched"] > 0
    assert 0 < f["held"]["median"] <= f["peak"]["median"] and f["held"]["max"] <= f["peak"]["max"]


@pytest.mark.xfail(strict=True, reason="issue 40 item 3 is not built: nothing bounds a ball from opposite sides "
                                       "before a joint presses on it, and one wrap rolls the 0.1 kg ball 78 mm "
                                       "(BENCHMARKS.md, 'Touch without pushing')")
def test_one_wrap_around_a_tenth_of_a_kilo_ball_on_the_table_moves_it_under_2mm():
    from explore3d.world.objects import sphere

    ex, s = _one_wrap_on_the_table(sphere(0.025, subdivisions=3), 0.1)
    assert ex.n_contacts > 0 and s["max_drift_m"] < 2e-3
