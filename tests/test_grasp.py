"""Grasping with the estimate (issue 25): the antipodal sampler's known answers and invariance,
execution on the truth, determinism, and ``explore3d grasp`` on a small run."""
from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from explore3d.grasp.antipodal import sample_grasps
from explore3d.grasp.gripper import GripperSpec
from explore3d.world.objects import load_object

BOX = (0.10, 0.06, 0.04)


def _box():
    return trimesh.creation.box(extents=BOX)


def test_box_grasps_are_antipodal_across_opposite_faces():
    """Known answer: every grasp on a box closes across two opposite faces: its axis along a box
    axis, its width that axis's extent, its contacts on the two faces, within the stroke."""
    box = _box()
    g = sample_grasps(box, 20, seed=1, table_z=-BOX[2] / 2)
    assert len(g) == 20
    grip = GripperSpec()
    for T, c, w in zip(g.poses, g.contacts, g.widths):
        k = int(np.argmax(np.abs(T[:3, 0])))
        assert abs(abs(T[k, 0]) - 1.0) < 1e-9  # the closing axis is a box axis
        assert w == pytest.approx(BOX[k], abs=1e-6) and w <= grip.stroke_m
        assert sorted(c[:, k]) == pytest.approx([-BOX[k] / 2, BOX[k] / 2], abs=1e-6)
    assert np.all(np.diff(g.quality) <= 0)  # best first
    assert np.all(g.angles == 0.0)


def test_no_grasp_on_a_sphere_larger_than_the_stroke():
    grip = GripperSpec()
    big = trimesh.creation.icosphere(subdivisions=3, radius=0.6 * grip.stroke_m)
    small = trimesh.creation.icosphere(subdivisions=3, radius=0.4 * grip.stroke_m)
    assert len(sample_grasps(big, 10, grip)) == 0
    assert len(sample_grasps(small, 10, grip)) == 10  # the same sampler finds the smaller one's


def test_grasps_move_with_the_mesh():
    """Rigid motion about the vertical (the approach order is by height, so the vertical stays):
    the grasps of the moved mesh are the moved grasps."""
    mesh = load_object("l_block")
    T = trimesh.transformations.rotation_matrix(0.7, [0, 0, 1])
    T[:3, 3] = [0.3, -0.2, 0.1]
    moved = mesh.copy()
    moved.apply_transform(T)
    a = sample_grasps(mesh, 8, seed=3, table_z=float(mesh.bounds[0, 2]))
    b = sample_grasps(moved, 8, seed=3, table_z=float(moved.bounds[0, 2]))
    assert len(a) == len(b) == 8
    np.testing.assert_allclose(b.poses, T @ a.poses, atol=1e-6)
    np.testing.assert_allclose(b.quality, a.quality, atol=1e-9)


def test_same_seed_same_grasps():
    mesh = load_object("u_channel")
    a, b = (sample_grasps(mesh, 6, seed=5) for _ in range(2))
    np.testing.assert_array_equal(a.poses, b.poses)
    c = sample_grasps(mesh, 6, seed=6)
    assert not np.array_equal(a.poses, c.poses)


def test_bad_gripper_and_inputs_are_refused():
    with pytest.raises(ValueError, match="stroke_m"):
        GripperSpec(stroke_m=-0.1)
    with pytest.raises(ValueError, match="tip_m"):
        GripperSpec(tip_m=0.2)
    with pytest.raises(ValueError, match="n \\(how many grasps\\)"):
        sample_grasps(_box(), 0)
    with pytest.raises(TypeError, match="trimesh.Trimesh"):
        sample_grasps(np.zeros((4, 3)), 3)


def test_wilson_interval_known_values():
    from explore3d.app.grasp import wilson_interval

    assert wilson_interval(5, 10) == pytest.approx((0.2366, 0.7634), abs=1e-4)
    assert wilson_interval(20, 20) == pytest.approx((0.8389, 1.0), abs=1e-4)
    assert wilson_interval(0, 0) == (0.0, 1.0)


@pytest.mark.slow
def test_a_true_grasp_holds_and_one_moved_off_the_box_fails():
    """Grasps planned on the true box hold when executed; the same top grasps moved back along
    their approach until the finger tips stop 20 mm above the box miss.  Executing twice gives the
    same outcomes and rises (one world per grasp)."""
    from explore3d.world.grasping import Outcome, execute_grasps

    box = _box()
    grip = GripperSpec()
    g = sample_grasps(box, 3, grip, seed=0, table_z=-BOX[2] / 2)
    runs = execute_grasps(box, g, grip)
    assert [r.outcome for r in runs] == [Outcome.HELD] * 3
    assert all(r.rise_m > 0.09 for r in runs)
    again = execute_grasps(box, g, grip)
    assert [r.rise_m for r in again] == [r.rise_m for r in runs]
    top = g.poses[:, 2, 2] < -0.95  # approaching from above
    assert top.any()
    for i in np.flatnonzero(top):
        off = g.select([i])
        T = off.poses[0]
        tips_z = T[2, 3] + grip.tip_m * T[2, 2]  # the finger tips' height at the grasp pose
        T[:3, 3] -= ((BOX[2] / 2 + 0.02 - tips_z) / -T[2, 2]) * T[:3, 2]  # back along the approach
        assert execute_grasps(box, off, grip)[0].outcome is Outcome.MISSED


def test_a_grasp_off_centre_pushes_the_object_by_its_offset():
    """Known answer of ``push_m``: a grasp planned on the true box closes without moving it (under
    1 mm); the same grasp moved 8 mm along its closing axis (less than the 10 mm clearance, so the
    approach clears the box) closes the coupled fingers about the moved centre, so the first finger
    pushes the box by most of those 8 mm before the second one meets it (6.8 mm measured: the
    soft finger coupling gives a little)."""
    from explore3d.world.grasping import execute_grasps

    box = _box()
    grip = GripperSpec()
    g = sample_grasps(box, 1, grip, seed=0, table_z=-BOX[2] / 2)
    assert execute_grasps(box, g, grip)[0].push_m < 1e-3
    off = g.select([0])
    off.poses[0][:3, 3] += 0.008 * off.poses[0][:3, 0]
    run = execute_grasps(box, off, grip)[0]
    assert 0.005 < run.push_m < 0.010, run.push_m


@pytest.mark.slow
def test_grasp_command_on_a_small_run(tmp_path, capsys):
    """``explore3d grasp`` on a small 3D run: report.json gains the four sources' rates with their
    intervals, grasps.json holds every grasp with its outcome, and a second call gives the same."""
    from explore3d import ArmSpec, write_arm_urdf
    from explore3d.app.cli import main

    arm = write_arm_urdf(ArmSpec(name="small16", n_links=16, link_length=0.02), tmp_path / "small16.urdf")
    out = tmp_path / "run"
    assert main(["run", "cube", "--out", str(out), "--arm", str(arm), *SMALL_RUN, "--no-pictures", "-q",
                 "--jobs", "1", "--grasp", "4"]) == 0
    from_run = json.loads((out / "report.json").read_text())
    assert set(from_run["timings"]["grasp"]) == {"estimate", "truth", "convex_hull", "early"}
    assert from_run["timings"]["grasp_s"] > 0
    capsys.readouterr()
    assert main(["grasp", str(out), "--n", "4"]) == 0
    printed = capsys.readouterr().out
    report = json.loads((out / "report.json").read_text())
    entry = report["grasp"]
    for name in ("estimate", "truth", "convex_hull", "early"):
        r = entry[name]
        assert r["planned"] == 4 and len(r["outcomes"]) == 4 and 0 <= r["held"] <= 4
        lo, hi = r["wilson_95"]
        assert 0.0 <= lo <= r["rate"] <= hi <= 1.0
        assert 0.0 <= r["push_median_m"] <= r["push_max_m"]
        assert name in printed
    assert entry["truth"]["held"] == 4  # grasps planned on the truth hold on it
    grasps = json.loads((out / "grasps.json").read_text())
    assert [g["outcome"] for g in grasps["estimate"]] == entry["estimate"]["outcomes"]
    assert (out / "grasps.png").stat().st_size > 0 and "grasps.json" in report["files"]
    assert main(["grasp", str(out), "--n", "4", "--no-pictures"]) == 0
    assert json.loads((out / "report.json").read_text())["grasp"]["estimate"]["outcomes"] == entry["estimate"]["outcomes"]
    # run --grasp 4 graded the same folder the same way
    assert from_run["grasp"] == entry


SMALL_RUN = ["--directions", "24", "--offsets", "1", "--angles", "1", "--attempts", "1", "--probes", "0"]


def test_a_sweep_grades_by_grasping(tmp_path):
    """The sweep key ``grasp``: each run's report row holds the grasp entry (its times in the
    timings column, not in the report) and the sweep report gains the per-source success columns."""
    from explore3d import ArmSpec, write_arm_urdf
    from explore3d.app.sweep import read_rows, run_sweep
    from explore3d.app.sweep_report import GRASP_COLUMNS, report_table

    arm = str(write_arm_urdf(ArmSpec(name="small16", n_links=16, link_length=0.02), tmp_path / "small16.urdf"))
    grid = {"arm": [arm], "directions": [24], "offsets": [1], "angles": [1], "attempts": [1], "probes": [0],
            "grasp": [0, 3]}
    s = run_sweep(["cube"], tmp_path / "s", grid, workers=1, progress=False)
    assert (s.ran, s.ok) == (2, 2)
    rows = read_rows(tmp_path / "s")
    graded = [r for r in rows if json.loads(r["settings"]).get("grasp")]
    plain = [r for r in rows if not json.loads(r["settings"]).get("grasp")]
    assert len(graded) == len(plain) == 1
    entry = json.loads(graded[0]["report"])["grasp"]
    assert "grasp" not in json.loads(plain[0]["report"])
    assert entry["truth"]["planned"] == 3 and entry["truth"]["held"] == 3
    assert "grasp" in json.loads(graded[0]["timings"])["timings"]
    assert graded[0]["percent_error"] == plain[0]["percent_error"]  # grading does not touch the run
    header, table = report_table(rows)
    assert all(c in header for c in GRASP_COLUMNS)
    row = table[rows.index(graded[0])]
    assert row[header.index("grasp_truth")] == 1.0
    assert row[header.index("grasp_estimate")] == entry["estimate"]["rate"]
    assert table[rows.index(plain[0])][header.index("grasp_truth")] is None


def test_grasp_command_refuses_a_folder_without_a_run(tmp_path, capsys):
    from explore3d.app.cli import main

    assert main(["grasp", str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "report.json not found" in err[0]
    assert main(["grasp", str(tmp_path), "--n", "0"]) == 2
    assert "--n must be an integer >= 1" in capsys.readouterr().err
