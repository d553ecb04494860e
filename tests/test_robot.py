"""The robot interface: what passes through the door, realistic sensing, logs that replay, and
proof that the exploration cannot see the world."""
import dataclasses
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pybullet
import pytest

from explore3d.arm.spec import ArmSpec
from explore3d.world.band import cached_band
from explore3d.strategy.encircle import ControlConfig, run_wrap
from explore3d.arm.kinematics import gravity_torques, point_jacobian
from explore3d.world.objects import cube
from explore3d.robot.interface import LogMismatchError, LogRobot, RecordingRobot, Robot, RobotLog, make_command
from explore3d.robot.sensing import SensorConfig
from explore3d.world.sim import ArmSimulation
from explore3d.core.settings import SimConfig

SMALL = ArmSpec(name="small12", n_links=12, link_length=0.025)
ROOT = Path(__file__).resolve().parents[1]

#: The PyBullet calls that read the world rather than the arm's own joints.
WORLD_QUERIES = ("getContactPoints", "getClosestPoints", "rayTest", "rayTestBatch", "getLinkState", "getLinkStates",
                 "getBasePositionAndOrientation", "getBaseVelocity", "getAABB", "getOverlappingObjects")

#: The only modules allowed to name them: the evaluation layer (truth and oracle) and the world's own
#: physics (world/support.py applies the support's rolling and spinning friction to the object, which
#: the Dantzig solver drops; it returns nothing, and the strategy cannot import the world).
EVALUATION_MODULES = {"world/quality.py", "world/replay.py", "geometry/sdf.py", "world/skin.py", "app/compare.py",
                      "world/calibration.py", "app/pictures.py", "world/scene.py", "world/support.py",
                      "world/grasping.py"}  # grasping: executing grasps on the truth (evaluation)


def _vertical_base():
    T = np.eye(4)
    T[:3, :3] = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
    T[:3, 3] = [0.1, -0.2, 0.3]
    return T


def _walk(obj, seen=None):
    """Every object reachable from ``obj`` through attributes and containers (not into functions)."""
    seen = set() if seen is None else seen
    if id(obj) in seen or isinstance(obj, (int, float, str, bool, type(None), np.ndarray, np.generic)):
        return
    seen.add(id(obj))
    yield obj
    items = obj.values() if isinstance(obj, dict) else obj if isinstance(obj, (list, tuple, set)) else \
        vars(obj).values() if hasattr(obj, "__dict__") and not callable(obj) else ()
    for v in items:
        yield from _walk(v, seen)


def test_the_robot_exposes_no_client_or_pybullet_handle():
    from pybullet_utils.bullet_client import BulletClient

    with ArmSimulation(SMALL, cube().vertices, cube().faces) as world:
        robot = world.robot()
        assert isinstance(robot, Robot)
        public = {n for n in dir(robot) if not n.startswith("_")}
        assert public <= {"spec", "dt", "gravity", "sensors", "base_pose", "start", "step", "reseed"}, public
        for o in _walk(robot):
            assert not isinstance(o, (BulletClient, ArmSimulation)), type(o)
            assert o is not pybullet
        for name, v in vars(robot).items():
            assert "client" not in name and not isinstance(v, BulletClient)


def test_jacobian_and_gravity_torques_match_pybullet():
    """The model the robot knows (numpy) against PyBullet: its Jacobian (reported in the base frame)
    and the torques its motors apply to hold the arm still (PyBullet's calculateInverseDynamics
    ignores a fixed base's orientation, so the static hold is the reference).  Self-collision is
    off: the random configurations fold links into each other, and a self-contact's forces load
    the joints too."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(3)
    for seed in range(3):
        T = np.eye(4)
        T[:3, :3] = Rotation.random(random_state=seed).as_matrix()
        T[:3, 3] = [0.1, -0.2, 0.3]
        q = rng.uniform(-0.5, 2.0, SMALL.n_links)
        with ArmSimulation(SMALL, config=SimConfig(self_collision=False)) as world:
            p, arm, n = world.client, world.arm, SMALL.n_links
            p.resetBasePositionAndOrientation(arm, T[:3, 3].tolist(), Rotation.from_matrix(T[:3, :3]).as_quat().tolist())
            for j in range(n):
                p.resetJointState(arm, j, q[j], 0.0)
            link, local = 7, np.array([0.01, 0.004, -0.003])
            J_base, _ = p.calculateJacobian(arm, link, local.tolist(), q.tolist(), [0.0] * n, [0.0] * n)
            assert np.allclose(T[:3, :3] @ np.array(J_base), point_jacobian(SMALL, q, link, local, T), atol=1e-12)
            p.setJointMotorControlArray(arm, list(range(n)), pybullet.POSITION_CONTROL, targetPositions=q.tolist(),
                                        forces=[50.0] * n)
            for _ in range(200):
                p.stepSimulation()
            held = np.array([s[3] for s in p.getJointStates(arm, list(range(n)))])
        g = gravity_torques(SMALL, q, T, (0, 0, -9.81))
        assert np.abs(g).max() > 0.005
        assert np.allclose(held, -g, atol=1e-5), held + g


def test_gravity_feed_forward_holds_the_arm_and_is_reported_as_motor_torque():
    """Straight arm held horizontal in a vertical plane: with the model's feed-forward the position
    loop carries nothing; the reported torque is the feed-forward, -gravity torques."""
    T = _vertical_base()
    q0 = np.zeros(SMALL.n_links)
    g = -gravity_torques(SMALL, q0, T, (0, 0, -9.81))
    assert np.abs(g).max() > 0.01
    with ArmSimulation(SMALL) as world:
        for ff, name in ((g, "feed-forward"), (np.zeros_like(g), "position loop alone")):
            robot = world.robot(SensorConfig.ideal())
            robot.start(T, q0)
            for _ in range(60):
                r = robot.step(make_command(SMALL, q0, tau_ff=ff))
            assert np.allclose(r.tau, g, atol=2e-3 if name == "feed-forward" else 0.05), (name, r.tau - g)
            if name == "feed-forward":
                assert np.abs(r.q).max() < 1e-6, r.q


def test_sensing_quantises_delays_and_seeds():
    cfg = SensorConfig()
    res = cfg.angle_resolution_rad
    assert res == pytest.approx(2 * np.pi / 4096)
    T = np.eye(4)
    cmds = [make_command(SMALL, np.r_[0.02 * i, np.zeros(SMALL.n_links - 1)]) for i in range(1, 30)]
    with ArmSimulation(SMALL) as world:
        def run(sensors, key=(0,)):
            robot = world.robot(sensors)
            robot.reseed(key)
            robot.start(T, np.zeros(SMALL.n_links))
            return [robot.step(c) for c in cmds]

        exact = run(SensorConfig.ideal())
        late = run(dataclasses.replace(SensorConfig.ideal(), delay_steps=1))
        real_a, real_b, real_c = run(cfg), run(cfg), run(cfg, key=(1,))
    for t in range(1, len(cmds)):
        assert np.array_equal(late[t].q, exact[t - 1].q) and np.array_equal(late[t].tau, exact[t - 1].tau)
    Q = np.array([r.q for r in real_a])
    assert np.allclose(Q / res, np.round(Q / res), atol=1e-9)
    tau = np.array([r.tau for r in real_a])
    assert np.allclose(tau / 1e-3, np.round(tau / 1e-3), atol=1e-6)
    assert all(np.array_equal(a.tau, b.tau) for a, b in zip(real_a, real_b))  # same seed: same readings
    assert any(not np.array_equal(a.tau, c.tau) for a, c in zip(real_a, real_c))  # another wrap: other noise
    assert np.abs(Q[1:] - np.array([r.q for r in exact])[:-1]).max() <= res / 2 + 1e-12


@pytest.mark.parametrize("bad", [dict(encoder_counts_per_turn=-1), dict(torque_noise_nm=float("nan")),
                                 dict(delay_steps=1.5), dict(velocity_resolution_rad_s=-0.1)])
def test_sensor_config_rejects_bad_values(bad):
    with pytest.raises(ValueError, match="SensorConfig"):
        SensorConfig(**bad)


def test_a_recorded_log_replays_to_the_same_detections(tmp_path):
    """A simulated wrap recorded through the door, saved, loaded and played back through LogRobot:
    the controller takes the same decisions (a real robot's log in this format works the same way)."""
    band = cached_band(SMALL, planar=True)
    m = cube()
    from explore3d.strategy.explore import ExploreConfig, wrap_poses, rough_bound

    c, r = rough_bound(m.vertices)
    pose = wrap_poses(SMALL, ExploreConfig(mode="planar", directions=1), c, r)[0]
    with ArmSimulation(SMALL, m.vertices, m.faces) as world:
        sim_robot = world.robot()
        sim_robot.reseed((0, 0))
        rec = RecordingRobot(sim_robot)
        live = run_wrap(rec, pose.T_world_base, band, attempts=2)
    assert sum(a.contact.sum() for a in live) > 0
    path = rec.log().save(tmp_path / "wrap.npz")
    log = RobotLog.load(path)
    assert log.n_motions == len(live) and log.n_steps == sum(a.steps for a in live) + len(live)
    player = LogRobot(log)
    replayed = run_wrap(player, pose.T_world_base, band, attempts=2)
    assert player.finished
    for a, b in zip(live, replayed):
        assert np.array_equal(a.q, b.q) and np.array_equal(a.contact, b.contact) and a.reasons == b.reasons
    # a controller that does something else is told so
    with pytest.raises(LogMismatchError, match="q_ref"):
        run_wrap(LogRobot(log), pose.T_world_base, band, attempts=2, cfg=ControlConfig(speed=2.0))


def test_a_bad_log_file_is_a_one_line_error(tmp_path):
    bad = tmp_path / "bad.npz"
    np.savez(bad, q=np.zeros((3, 2)))
    with pytest.raises(ValueError, match="lacks") as e:
        RobotLog.load(bad)
    assert "\n" not in str(e.value)
    with pytest.raises(ValueError, match="does not exist"):
        RobotLog.load(tmp_path / "missing.npz")


def test_band_is_measured_for_every_joint_and_cached(tmp_path, monkeypatch):
    from explore3d.world import band as band_mod

    monkeypatch.setenv("EXPLORE3D_CACHE_DIR", str(tmp_path))
    arm = ArmSpec(name="tiny8", n_links=8, link_length=0.03)
    cached_band.cache_clear()
    b1 = cached_band(arm, planar=True)
    files = list((tmp_path / "bands").glob("*.json"))
    assert len(files) == 1 and b1.provenance["cache"] == "computed"
    prov = b1.provenance
    # free motion covers every joint (no stop at max_curl), and the band is band_factor x the measured maxima
    free_steps = np.array(prov["free_sweep_steps"])
    assert free_steps.shape == (arm.n_links,) and (free_steps > 0).all()
    # every joint swept 0 -> its limit: the slowest (proximal) joints take the most steps
    assert free_steps[0] == free_steps.max()
    meas = np.maximum(prov["free_swept_max_rad"], prov["impact_swept_max_rad"])
    assert np.allclose(b1.swept, ControlConfig().band_factor * meas)
    assert prov["impact_wraps"] > 0 and [p["pass"] for p in prov["impact_passes"]] == ["measure"] * 2 + ["verify"] * 2
    assert sum(p["contacts"] for p in prov["impact_passes"]) > 0  # the known objects were touched
    cached_band.cache_clear()
    calls = []
    monkeypatch.setattr(band_mod, "calibrate_band", lambda *a, **k: calls.append(a))
    b2 = cached_band(arm, planar=True)
    assert not calls and np.array_equal(b1.swept, b2.swept) and np.array_equal(b1.other, b2.other)
    cached_band.cache_clear()


ORACLE_FREE = textwrap.dedent("""
    import sys, pybullet
    names = {names!r}
    for n in names:
        if hasattr(pybullet, n):
            delattr(pybullet, n)
    assert not any(hasattr(pybullet, n) for n in names)
    import numpy as np
    from explore3d.arm.spec import ArmSpec
    from explore3d.strategy.active import ProbeConfig
    from explore3d.strategy.explore import ExploreConfig
    from explore3d.world.objects import cube
    from explore3d.app.pipeline import run
    arm = ArmSpec(name="small12", n_links=12, link_length=0.025)
    res = run(cube(), arm, ExploreConfig(directions=24, angles=1, jobs=2, record=True,
                                         probes=ProbeConfig(rounds=1, targets=2, fingers=2, pokes=2)))
    ex = res.exploration
    # a round of probe wraps ran in the workers, and the estimate was carved with the swept space
    assert len(ex.probe_rounds) == 1 and ex.n_wraps == 24 + ex.probe_rounds[0]["wraps"] > 24
    assert any(p.label.startswith("finger") for p in ex.poses)  # finger probes planned on the estimate ran
    assert any(p.label.startswith("poke") for p in ex.poses)  # and tip pokes
    assert len(ex.swept) == ex.n_wraps and res.carved is not None
    assert ex.n_contacts > 0 and ex.config.control.gravity_compensation and ex.logs is not None
    # the arm collided with itself and told it from the object by its own model: attempts ended so
    from explore3d.strategy.encircle import StopReason
    assert ex.config.sim.self_collision and ex.config.control.self_contact_action == "end"
    assert any(r is StopReason.SELF for w in ex.attempts for a in w for r in a.reasons)
    # the wraps' planes are tilted: gravity compensation actually ran (non-zero feed-forward)
    assert max(np.abs(l.tau_ff).max() for l in ex.logs) > 0
    # the hull took contacts localised from the settled readings, their heights resolved
    assert ex.config.points == "contacts" and ex.contacts.used.sum() == len(ex.points) >= 4
    assert np.array_equal(ex.points, ex.contacts.points[ex.contacts.used])
    # the curl-back encirclement too: its hairpin moves between sweeps happened
    from explore3d.strategy.encircle import CurlBack
    from explore3d.world.explore import explore
    cb = explore(cube(), arm, ExploreConfig(directions=3, angles=1, jobs=2, record=True, probes=None,
                                            curl_back=CurlBack()))
    assert cb.n_contacts > 0 and any((a.trajectory_ref < -0.3).any() for w in cb.attempts for a in w)
    print("ORACLE-FREE-OK", ex.n_contacts, len(ex.points), round(res.error.percent, 2))
""")


def test_exploration_runs_with_every_world_query_removed_from_pybullet(tmp_path):
    """The world queries are deleted from the pybullet module *before* explore3d is imported, so no
    alias bound at import time escapes; a 3D exploration with gravity compensation, two worker
    processes, the contact localisation, the free space, a round of probes (wraps, fingers and tip pokes) aimed from
    the estimate,
    self-contacts ending attempts and the carved reconstruction runs in that process and its
    workers; so does a curl-back exploration."""
    env = {**os.environ, "EXPLORE3D_CACHE_DIR": str(tmp_path)}
    out = subprocess.run([sys.executable, "-c", ORACLE_FREE.format(names=WORLD_QUERIES)], capture_output=True,
                         text=True, env=env, cwd=tmp_path, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "ORACLE-FREE-OK" in out.stdout


ORACLE_FREE_TABLE = textwrap.dedent("""
    import pybullet
    import numpy as np
    from explore3d.arm.spec import ArmSpec
    from explore3d.world.objects import cube
    from explore3d.app.pipeline import run
    from explore3d.world.scene import scene_explore_config, settle_scene
    import explore3d.world.support  # the world's own physics (the support's friction) binds its queries here
    arm = ArmSpec(name="small12", n_links=12, link_length=0.025)
    cfg = scene_explore_config("table", spec=arm, table_heights=3, table_angles=3, directions=4, angles=1)
    m = cube(0.04)
    setup = settle_scene(m, cfg.scene, arm, cfg.sim)  # the evaluation's setup may read the pose
    names = {names!r}
    for n in names:
        if hasattr(pybullet, n):
            delattr(pybullet, n)
    assert not any(hasattr(pybullet, n) for n in names)
    res = run(m, arm, cfg, setup=setup)
    ex = res.exploration
    assert ex.config.scene.resting and ex.config.scene.persistent and ex.table_z == setup.table_z
    assert ex.config.control.detector == "torque"  # the table's default: every joint's external torque watched
    assert ex.n_contacts > 0 and len(ex.moved) == ex.n_wraps
    assert abs(res.estimate.bounds[0, 2] - setup.table_z) < 1e-9  # the estimate stands on the table
    assert any(p.label.startswith("top search") for p in ex.poses)  # the search for the top ran too
    print("ORACLE-FREE-TABLE-OK", ex.n_wraps, ex.n_contacts, round(res.error.percent, 2))
""")


def test_table_scene_exploration_runs_with_every_world_query_removed_from_pybullet(tmp_path):
    """The table scene: the object is settled first (the evaluation's setup reads its pose), then the
    world queries are deleted from pybullet and the persistent world's exploration with the
    external-torque detector (the arm's model against its motor torques), the motion
    flags and the estimate on the table run without them (the world's own physics, which applies
    the support's rolling friction to the object, bound its queries when imported)."""
    out = subprocess.run([sys.executable, "-c", ORACLE_FREE_TABLE.format(names=WORLD_QUERIES)], capture_output=True,
                         text=True, cwd=tmp_path, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "ORACLE-FREE-TABLE-OK" in out.stdout


def test_no_module_outside_the_evaluation_layer_names_a_world_query():
    pattern = re.compile("|".join(WORLD_QUERIES))
    offenders = []
    for path in sorted((ROOT / "explore3d").rglob("*.py")):
        rel = path.relative_to(ROOT / "explore3d")
        if rel.as_posix() in EVALUATION_MODULES:
            continue
        for i, line in enumerate(path.read_text().splitlines(), 1):
            if pattern.search(line):
                offenders.append(f"{rel}:{i}: {line.strip()}")
    assert not offenders, offenders


def test_factory_bands_are_those_of_the_current_defaults():
    """The bands shipped in explore3d/data are exactly the built-in arms' default settings; a
    change of any default (or of the protocol or version) must regenerate them
    (``python scripts/make_bands.py``), or the first run would silently recalibrate."""
    from explore3d.arm.urdf import load_arm
    from explore3d.world.band import FACTORY_SETTINGS, band_cache_key, factory_band_path
    from explore3d.core.settings import SimConfig

    keys = {band_cache_key(load_arm(a), ControlConfig(), SimConfig(), SensorConfig(), p) for a, p in FACTORY_SETTINGS}
    shipped = {p.stem.removeprefix("band-") for p in factory_band_path("x").parent.glob("band-*.json")}
    assert shipped == keys, "regenerate the factory bands: python scripts/make_bands.py"


def test_factory_band_is_what_the_calibration_measures(monkeypatch, tmp_path):
    """The paper arm's shipped planar band equals a fresh calibration on this code (bit for bit:
    the calibration is deterministic), and cached_band reads it without calibrating."""
    from explore3d.world import band as band_mod
    from explore3d.arm.urdf import load_arm
    from explore3d.core.settings import SimConfig

    spec = load_arm("paper")
    fresh = band_mod.calibrate_band(spec, ControlConfig(), SimConfig(), SensorConfig(), planar=True)
    monkeypatch.setenv("EXPLORE3D_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(band_mod, "calibrate_band", lambda *a, **k: pytest.fail("calibrated instead of reading"))
    cached_band.cache_clear()
    shipped = cached_band(spec, ControlConfig(), SimConfig(), SensorConfig(), True)
    cached_band.cache_clear()
    assert "data/band-" in shipped.provenance["cache"]
    assert np.array_equal(shipped.swept, fresh.swept) and np.array_equal(shipped.other, fresh.other)


def test_callers_needing_one_uncached_band_at_once_measure_it_once(monkeypatch, tmp_path):
    """Three callers ask for the same band, not yet cached, at the same time (as a sweep's workers
    on a new arm do): one measures it (a stand-in calibration taking 0.5 s), the others wait on its
    lock and read what it stored; a second setting is measured on its own."""
    import concurrent.futures
    import time

    from explore3d.feeling.detect import ContactBand
    from explore3d.world import band as band_mod

    calls = []

    def slow_calibration(spec, *args, **kwargs):
        calls.append(spec.n_links)
        time.sleep(0.5)
        return ContactBand(swept=np.full(spec.n_links, 0.01), other=np.full(spec.n_links, 0.02), provenance={})

    monkeypatch.setenv("EXPLORE3D_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(band_mod, "calibrate_band", slow_calibration)
    uncached = band_mod.cached_band.__wrapped__  # past the in-memory cache: each call reads the disk
    specs = [SMALL] * 3 + [ArmSpec(name="small8", n_links=8, link_length=0.03)]
    with concurrent.futures.ThreadPoolExecutor(4) as pool:
        bands = list(pool.map(lambda s: uncached(s, planar=True), specs))
    assert sorted(calls) == [8, 12]
    sources = [b.provenance["cache"] for b in bands[:3]]
    assert sources.count("computed") == 1 and all(s.endswith(".json") for s in sources if s != "computed")
    assert all(np.array_equal(b.swept, bands[0].swept) for b in bands[:3])
    assert bands[3].provenance["cache"] == "computed"


# --- an arm read from any URDF (issue 26) -------------------------------------------------------------

def _plain_urdf(spec):
    """explore3d's URDF of ``spec`` without the embedded spec comment: what another tool would write."""
    import re

    from explore3d.arm.urdf import arm_urdf

    return re.sub(r"<!-- explore3d-arm-spec:.*?-->", "", arm_urdf(spec))


def test_an_arm_is_read_from_its_joints_and_links(tmp_path):
    """A URDF without explore3d's comment gives the same ArmSpec from its joints and links
    (to the URDF's printed precision), through load_arm as through the file."""
    from explore3d.arm.spec import DEFAULT_ARM, PAPER_ARM, ArmSpec
    from explore3d.arm.urdf import load_arm

    for spec in (DEFAULT_ARM, PAPER_ARM, ArmSpec(name="small16", n_links=16, link_length=0.02, link_mass=0.02)):
        path = tmp_path / f"{spec.name}.urdf"
        path.write_text(_plain_urdf(spec))
        got = load_arm(str(path))
        for k, v in spec.to_dict().items():
            assert getattr(got, k) == (v if isinstance(v, (str, int)) else pytest.approx(v, rel=1e-5)), k


@pytest.mark.parametrize("edit,words", [
    (lambda t: t.replace('<joint name="joint3" type="revolute">', '<joint name="joint3" type="prismatic">'),
     "joint 'joint3' is 'prismatic'"),
    (lambda t: t.replace('<axis xyz="0 0 1"/>', '<axis xyz="0 1 0"/>', 1), "turns about"),
    (lambda t: t.replace('<parent link="link4"/>', '<parent link="link2"/>'), "more than one child joint"),
    (lambda t: t.replace('<box size="0.02 0.008 0.01"/></geometry></collision>',
                         '<box size="0.02 0.012 0.01"/></geometry></collision>', 1), "box sizes differ"),
    (lambda t: "<robot><link", "not valid XML"),
])
def test_a_urdf_arm_spec_cannot_hold_is_refused(tmp_path, edit, words):
    from explore3d.arm.spec import DEFAULT_ARM
    from explore3d.arm.urdf import load_arm

    path = tmp_path / "arm.urdf"
    path.write_text(edit(_plain_urdf(DEFAULT_ARM)))
    with pytest.raises(ValueError, match=words.replace("(", r"\(").replace(")", r"\)")) as exc:
        load_arm(str(path))
    assert "\n" not in str(exc.value)
