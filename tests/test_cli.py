"""Tests of the command line (explore3d.app.cli.main, called in-process)."""
import json
import math
import sys
import types
from pathlib import Path

import numpy as np
import pytest
import trimesh

from explore3d.app.cli import build_parser, main
from explore3d.app.settings import explore_config, resolve_run_options
from explore3d.strategy.explore import ExploreConfig
from explore3d.world.objects import builtin_object_names, load_object

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line_error(err, *words):
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("explore3d: error: ")
    assert "Traceback" not in err
    for w in words:
        assert w.lower() in lines[0].lower(), lines[0]


#: A small arm (16 x 20 mm, reach 0.32 m) keeps each simulated run here to about a second.
@pytest.fixture(scope="module")
def small_arm(tmp_path_factory):
    from explore3d import ArmSpec, write_arm_urdf

    return write_arm_urdf(ArmSpec(name="small16", n_links=16, link_length=0.02),
                          tmp_path_factory.mktemp("arm") / "small16.urdf")


# --- help and simple commands --------------------------------------------------------------------

@pytest.mark.parametrize("cmd", [[], ["run"], ["reconstruct"], ["evaluate"], ["table1"], ["arm"], ["objects"]])
def test_help(capsys, cmd):
    code, out, _ = run(capsys, *cmd, "--help")
    assert code == 0
    assert "usage: explore3d" in out


def test_no_command_is_usage_error(capsys):
    code, _, err = run(capsys)
    assert code == 2
    assert_one_line_error(err)


def test_objects_lists_builtins(capsys):
    code, out, _ = run(capsys, "objects", "--json")
    assert code == 0
    rows = json.loads(out)
    assert [r["name"] for r in rows] == builtin_object_names()
    cube = rows[0]
    np.testing.assert_allclose(cube["extents_m"], [0.08] * 3)
    assert cube["volume_m3"] == pytest.approx(0.08 ** 3)
    code, out, _ = run(capsys, "objects")
    assert all(name in out for name in builtin_object_names())


def test_arm_writes_loadable_urdf(tmp_path, capsys):
    from explore3d.arm.urdf import load_arm

    path = tmp_path / "tiny.urdf"
    code, _, err = run(capsys, "arm", "--out", str(path), "--n-links", "8", "--link-length", "0.02",
                       "--name", "tiny")
    assert code == 0, err
    spec = load_arm(str(path))
    assert (spec.n_links, spec.link_length, spec.name) == (8, 0.02, "tiny")
    assert spec.link_width == load_arm("default").link_width  # untouched fields come from --base


@pytest.mark.parametrize("argv,word", [(["--n-links", "0"], "n-links"), (["--link-length", "-1"], "link-length"),
                                       (["--joint-upper", "x"], "joint-upper"), (["--base", "nope"], "nope")])
def test_arm_bad_values(tmp_path, capsys, argv, word):
    code, _, err = run(capsys, "arm", "--out", str(tmp_path / "a.urdf"), *argv)
    assert code == 2
    assert_one_line_error(err, word)
    assert not (tmp_path / "a.urdf").exists()


# --- configuration parsing -----------------------------------------------------------------------

def _parse(*argv):
    return build_parser().parse_args(["run", *argv])


def test_flags_into_explore_config():
    opts = resolve_run_options(_parse("--out", "x", "--mode", "planar", "--directions", "2", "--attempts", "3"))
    cfg = explore_config(opts)
    assert isinstance(cfg, ExploreConfig)
    assert (cfg.mode, cfg.directions, cfg.attempts) == ("planar", 2, 3)
    assert cfg.offsets == ExploreConfig().offsets  # unset: the dataclass default
    import inspect

    from explore3d.app.pipeline import run as api_run

    # the command line's default coarseness is the API's
    assert (opts["object"], opts["a"], opts["format"]) == ("cube", inspect.signature(api_run).parameters["a"].default, "obj")
    assert cfg.jobs is None  # all cores unless told


def test_toml_config_and_flag_override(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text('object = "sphere"\nout = "o"\nmode = "planar"\ndirections = 3\na = 0.5\nmethod = "spherical"\n'
                   'format = "stl"\nn_along = 7\nmirrored = true\n')
    opts = resolve_run_options(_parse("--config", str(cfg), "--a", "0.3", "--directions", "2"))
    assert (opts["object"], opts["out"], opts["method"], opts["format"]) == ("sphere", "o", "spherical", "stl")
    assert opts["a"] == 0.3 and opts["directions"] == 2  # flags win
    c = explore_config(opts)
    assert (c.mode, c.directions, c.n_along, c.mirrored) == ("planar", 2, 7, True)


@pytest.mark.parametrize("text,word", [("bogus = 1\n", "bogus"), ("a = -1\n", "a"), ("jobs = 0\n", "jobs"),
                                       ("format = \"dae\"\n", "dae"), ("a = [\n", "toml"),
                                       ("mirrored = 3\n", "mirrored")])
def test_bad_toml_is_usage_error(tmp_path, capsys, text, word):
    cfg = tmp_path / "c.toml"
    cfg.write_text(text)
    code, _, err = run(capsys, "run", "--config", str(cfg), "--out", str(tmp_path / "o"))
    assert code == 2
    assert_one_line_error(err, word)


# --- bad inputs of run (all fail before any simulation) --------------------------------------------

@pytest.mark.parametrize("argv,word", [
    (["--a", "abc"], "number"),
    (["--a", "0"], "> 0"),
    (["--a", "-0.5"], "> 0"),
    (["--directions", "two"], "directions"),
    (["--attempts", "0"], "attempts"),
    (["--jobs", "0"], "jobs"),
    (["--format", "dae"], "dae"),
    (["--mode", "4d"], "4d"),
    (["--arm", "octopus"], "octopus"),
    (["nonesuch"], "unknown object"),
    (["--scale", "1", "--size", "1"], "not allowed"),
    (["--bogus-flag"], "bogus-flag"),
])
def test_run_usage_errors(tmp_path, capsys, argv, word):
    code, _, err = run(capsys, "run", "--out", str(tmp_path / "o"), *argv)
    assert code == 2
    assert_one_line_error(err, word)


def test_run_needs_out(capsys):
    code, _, err = run(capsys, "run", "cube")
    assert code == 2
    assert_one_line_error(err, "--out")


def _open_cube(path):
    """A cylinder without its top cap: a 32-edge hole that load_object does not fill."""
    m = trimesh.creation.cylinder(radius=0.03, height=0.05, sections=32)
    keep = m.face_normals[:, 2] < 0.9
    trimesh.Trimesh(m.vertices, m.faces[keep], process=False).export(str(path))
    return path


@pytest.mark.parametrize("make,word", [
    (lambda d: d / "missing.stl", "not found"),
    (lambda d: (d / "notes.stl").write_text("this is not a mesh\n") and d / "notes.stl", "notes.stl"),
    (lambda d: (d / "empty.obj").write_bytes(b"") or d / "empty.obj", "empty.obj"),
    (lambda d: _open_cube(d / "open.stl"), "not a closed volume"),
])
def test_run_bad_object_files(tmp_path, capsys, make, word):
    path = make(tmp_path)
    code, _, err = run(capsys, "run", str(path), "--out", str(tmp_path / "o"), "-q")
    assert code == 1
    assert_one_line_error(err, word)
    assert not (tmp_path / "o" / "report.json").exists()


def test_run_unwritable_output(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    code, _, err = run(capsys, "run", "--out", str(blocker / "sub"), "-q")
    assert code == 1
    assert_one_line_error(err, "output folder")


def test_run_no_contacts_writes_report(tmp_path, capsys, small_arm):
    """A real exploration that touches nothing (the robot is told the object is 1 m away): exit 1,
    a one-line error naming the fix, and a report of the wraps that were run."""
    out = tmp_path / "o"
    code, _, err = run(capsys, "run", "cube", "--out", str(out), "--arm", str(small_arm), "--mode", "planar",
                       "--directions", "1", "--attempts", "1", "--centre", "1,0,0", "--radius", "0.06", "-q")
    assert code == 1
    assert_one_line_error(err, "no contacts", "--centre", "--size", "--arm")
    report = json.loads((out / "report.json").read_text())
    assert "no contact" in report["error"] and "--centre" in report["error"]  # the library's message
    assert report["n_contacts"] == 0 and report["n_wraps"] == 1 and report["steps"] > 0
    assert "percent_error" not in report
    assert (out / "points.ply").exists() == (report["n_points"] > 0)
    assert report["config"]["centre_m"] == [1.0, 0.0, 0.0] and report["config"]["radius_m"] == 0.06
    assert not (out / "estimate.obj").exists()


@pytest.mark.parametrize("argv,word", [(["--centre", "1,0"], "x,y,z"), (["--centre", "a,b,c"], "centre"),
                                       (["--radius", "0"], "> 0"), (["--radius", "-1"], "radius")])
def test_run_bad_rough_bound(tmp_path, capsys, argv, word):
    code, _, err = run(capsys, "run", "cube", "--out", str(tmp_path / "o"), *argv)
    assert code == 2
    assert_one_line_error(err, word)


# --- reconstruct and evaluate ----------------------------------------------------------------------

def test_reconstruct_sphere_points(tmp_path, capsys):
    from explore3d.app.export import write_points_ply

    rng = np.random.default_rng(3)
    v = rng.normal(size=(400, 3))
    P = 0.05 * v / np.linalg.norm(v, axis=1, keepdims=True) + [0.1, 0.0, 0.02]
    write_points_ply(P, tmp_path / "p.ply")
    code, _, err = run(capsys, "reconstruct", str(tmp_path / "p.ply"), "--out", str(tmp_path / "m.stl"))
    assert code == 0, err
    m = trimesh.load(str(tmp_path / "m.stl"))
    assert m.is_watertight
    # points on a sphere are all on the inverse hull: the result is their convex hull
    assert m.volume == pytest.approx(trimesh.convex.convex_hull(P).volume, rel=1e-4)


def test_reconstruct_implicit_estimator_reads_the_normals(tmp_path, capsys):
    """--estimator implicit fits the points and their nx, ny, nz; without normals it says so."""
    from explore3d import load_object
    from explore3d.app.export import write_points_ply

    mesh = load_object("l_block")
    P, fi = trimesh.sample.sample_surface(mesh, 3000, seed=np.random.default_rng(0))
    N = mesh.face_normals[fi]
    write_points_ply(P, tmp_path / "n.ply", extra={"nx": N[:, 0], "ny": N[:, 1], "nz": N[:, 2]})
    code, _, err = run(capsys, "reconstruct", str(tmp_path / "n.ply"), "--out", str(tmp_path / "m.obj"),
                       "--estimator", "implicit")
    assert code == 0, err
    est = trimesh.load(str(tmp_path / "m.obj"))
    assert est.is_watertight
    assert abs(est.volume - mesh.volume) / mesh.volume < 0.05  # the L, which the hull about its midrange bridges
    write_points_ply(P, tmp_path / "p.ply")
    code, _, err = run(capsys, "reconstruct", str(tmp_path / "p.ply"), "--out", str(tmp_path / "m.obj"),
                       "--estimator", "implicit")
    assert code == 2
    assert_one_line_error(err, "normals")


def test_reconstruct_planar_points_to_polygon(tmp_path, capsys):
    from explore3d.app.export import write_points_ply

    t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    P = np.column_stack([0.04 * np.cos(t), 0.04 * np.sin(t)])
    write_points_ply(P, tmp_path / "p.ply")
    code, _, err = run(capsys, "reconstruct", str(tmp_path / "p.ply"), "--out", str(tmp_path / "poly.json"),
                       "--centre", "0,0")
    assert code == 0, err
    ring = np.array(json.loads((tmp_path / "poly.json").read_text()))
    assert ring.shape == (60, 2)
    code, _, err = run(capsys, "reconstruct", str(tmp_path / "p.ply"), "--out", str(tmp_path / "m.obj"))
    assert code == 2
    assert_one_line_error(err, "--height")


@pytest.mark.parametrize("argv,code_,word", [
    (["missing.ply", "--out", "m.obj"], 1, "not found"),
    (["p.ply", "--out", "m.obj", "--a", "0"], 2, "> 0"),
    (["p.ply", "--out", "m.obj", "--centre", "middle"], 2, "centre"),
    (["p.ply", "--out", "m.dae"], 2, "dae"),
])
def test_reconstruct_errors(tmp_path, capsys, monkeypatch, argv, code_, word):
    from explore3d.app.export import write_points_ply

    write_points_ply(np.random.default_rng(0).normal(size=(30, 3)), tmp_path / "p.ply")
    monkeypatch.chdir(tmp_path)
    code, _, err = run(capsys, "reconstruct", *argv)
    assert code == code_
    assert_one_line_error(err, word)


def test_evaluate_meshes_known_answer(tmp_path, capsys):
    from explore3d.app.export import write_mesh

    big = load_object("cube", scale=1.1)  # about the cube's centre (the origin)
    write_mesh(big, tmp_path / "big.off")
    code, out, err = run(capsys, "evaluate", str(tmp_path / "big.off"), "cube", "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["percent"] == pytest.approx(100 * (1.1 ** 3 - 1), rel=1e-6)
    assert d["iou"] == pytest.approx(1 / 1.1 ** 3, rel=1e-6)


def test_evaluate_polygons(tmp_path, capsys):
    (tmp_path / "a.json").write_text(json.dumps([[0, 0], [1, 0], [1, 1], [0, 1]]))
    (tmp_path / "b.json").write_text(json.dumps([[0.5, 0], [1.5, 0], [1.5, 1], [0.5, 1]]))
    code, out, err = run(capsys, "evaluate", str(tmp_path / "b.json"), str(tmp_path / "a.json"))
    assert code == 0, err
    d = json.loads(out.strip().splitlines()[-1])
    assert d["percent"] == pytest.approx(100.0)  # A_err = 1 + 1 - 2 * 0.5
    assert "IoU" in out


def test_evaluate_bad_inputs(tmp_path, capsys):
    (tmp_path / "bad.json").write_text("[[0, 0], [1]]")
    code, _, err = run(capsys, "evaluate", str(tmp_path / "bad.json"), str(tmp_path / "bad.json"))
    assert code == 1
    assert_one_line_error(err, "bad.json")
    code, _, err = run(capsys, "evaluate", str(_open_cube(tmp_path / "open.stl")), "cube")
    assert code == 1
    assert_one_line_error(err, "closed")


# --- table1 (the lead's module; only the wiring is tested here) --------------------------------------

def test_table1_wiring(capsys, monkeypatch):
    rows = [{"case": "cube", "paper_area_error_m2": 1e-4, "paper_percent": 2.0, "area_error_m2": 5e-5, "percent": 1.0}]
    fake = types.ModuleType("explore3d.app.table1")
    calls = []
    fake.table1_rows = lambda **kw: calls.append(kw) or rows
    monkeypatch.setitem(sys.modules, "explore3d.app.table1", fake)
    monkeypatch.delattr("explore3d.app.table1", raising=False)  # the package attribute, if the real one was imported
    code, out, _ = run(capsys, "table1", "--json")
    assert code == 0
    assert json.loads(out) == rows
    code, out, _ = run(capsys, "table1", "--json", "--a", "0.1", "--seed", "3")
    assert code == 0 and calls[-1] == {"a": 0.1, "seed": 3}
    code, _, err = run(capsys, "table1", "--a", "0")
    assert code == 2
    assert_one_line_error(err, "> 0")
    code, out, _ = run(capsys, "table1")
    assert code == 0 and "cube" in out and "2.00" in out


# --- end to end ----------------------------------------------------------------------------------

def test_run_planar_end_to_end(tmp_path, capsys):
    import pybullet as p

    from explore3d.app.export import read_points_ply
    from explore3d.geometry.metrics import shape_error
    from explore3d.world.objects import cross_section
    from shapely.geometry import Polygon

    arm = tmp_path / "tiny.urdf"
    assert main(["arm", "--out", str(arm), "--n-links", "16", "--link-length", "0.02"]) == 0
    out = tmp_path / "out"
    code, stdout, err = run(capsys, "run", "cube", "--out", str(out), "--arm", str(arm), "--mode", "planar",
                            "--directions", "3", "--format", "off", "--quality", "-q")
    assert code == 0, err
    report = json.loads((out / "report.json").read_text())
    assert report["object"] == "cube" and report["mode"] == "planar" and report["n_wraps"] == 3
    assert report["config"]["explore"]["directions"] == 3
    # the estimate's convex hull (a polygon here): at least the estimate's area, centred near the cube's axis
    ch = report["estimate_convex_hull"]
    assert ch["size"] >= report["estimate_size"] * (1 - 1e-9) and len(ch["centre_m"]) == 2
    assert np.hypot(*ch["centre_m"]) < 0.01
    # the contact-quality figures, evaluated after the run against the true cube
    assert report["config"]["quality"] and report["config"]["explore"]["record"]
    assert 0 < report["timings"]["quality_s"] < report["timings"]["total_s"]
    assert report["timings"]["explore_s"] <= report["timings"]["run_s"] <= report["timings"]["total_s"]
    cq = report["contact_quality"]
    assert cq["n_detections"] == report["n_contacts"] and cq["n_attempts"] == 12  # 3 wraps x 4 attempts
    assert 0.0 <= cq["false_fraction"] <= 1.0 and cq["penetration_max_m"] < 1e-3
    assert report["config"]["arm"]["n_links"] == 16
    # the sensing and the measured per-joint contact band are recorded
    assert report["config"]["explore"]["sensors"]["encoder_counts_per_turn"] == 4096
    band = report["contact_band"]
    assert len(band["swept_rad"]) == len(band["other_rad"]) == 16 and band["provenance"]["free_sweep_steps"]
    assert set(report["versions"]) >= {"explore3d", "numpy", "scipy", "trimesh", "pybullet", "shapely"}
    for k in ("object", "mode", "arm", "n_wraps", "n_points", "a", "method", "percent_error", "iou", "chamfer_m",
              "hausdorff_m", "true_size", "estimate_size", "wall_s", "sim_s", "steps", "config", "versions"):
        assert k in report, k

    # the reported error is the error of the written polygon against the section at the centre
    poly = Polygon(json.loads((out / "estimate_polygon.json").read_text()))
    err_ = shape_error(poly, cross_section(load_object("cube"), 0.0))
    assert report["percent_error"] == pytest.approx(err_.percent, rel=1e-9)
    assert report["true_size"] == pytest.approx(0.08 ** 2)

    # extruded estimate: the polygon over the arm's sensed height band (its plane +- half a link height)
    m = trimesh.load(str(out / "estimate.off"))
    h = report["config"]["arm"]["link_height"]
    np.testing.assert_allclose(report["estimate_z_band_m"], [-h / 2, h / 2], atol=1e-12)
    np.testing.assert_allclose(m.bounds[:, 2], [-h / 2, h / 2], atol=1e-7)
    assert m.volume == pytest.approx(poly.area * h, rel=1e-5)

    pts, props = read_points_ply(out / "points.ply", with_properties=True)
    assert len(pts) == report["n_points"]
    np.testing.assert_array_equal(np.unique(props["wrap"]), [0, 1, 2])
    np.testing.assert_allclose(pts[:, 2], 0.0)

    cid = p.connect(p.DIRECT)
    try:
        p.loadURDF(str(out / "estimate.urdf"), physicsClientId=cid)  # via the OBJ copy of the OFF
    finally:
        p.disconnect(cid)

    for png in ("figure.png", "overview.png"):
        data = (out / png).read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 5000
    assert sorted(report["files"]) == sorted(f.name for f in out.iterdir())

    # reconstruct from the written points gives the run's polygon (float32 storage aside)
    # with the run's rough centre and radius
    centre = ",".join(str(x) for x in report["config"]["centre_m"])
    code, _, err = run(capsys, "reconstruct", str(out / "points.ply"), "--out", str(tmp_path / "re.json"),
                       "--a", str(report["a"]), "--centre", centre, "--radius", str(report["config"]["radius_m"]))
    assert code == 0, err
    again = Polygon(json.loads((tmp_path / "re.json").read_text()))
    assert again.area == pytest.approx(poly.area, rel=1e-5)
    assert again.symmetric_difference(poly).area < 1e-6 * poly.area


# --- run is explore3d.run; every built-in object and a pybullet_data mesh ----------------------------

#: Small explorations the localised contacts (the default) give a hull from: planar 3 directions x
#: 4 attempts (the planar default), 3D 24 planes x 1 angle and one round of probes with two finger
#: probes and two tip pokes (the default's 12 fingers cost a test as much as the 24 planes).
_SWEEPS_3D = ["--mode", "3d", "--directions", "24", "--offsets", "1", "--angles", "1", "--attempts", "1"]
_FAST = {"planar": ["--mode", "planar", "--directions", "3"],
         "3d": [*_SWEEPS_3D, "--probes", "1", "--fingers", "2", "--pokes", "2"]}
#: Every object's run (test_run_every_object): half the directions, the same probe round (the
#: facts it checks hold for any number of wraps; the suite runs it on ten objects).
_EVERY = {"planar": _FAST["planar"],
          "3d": ["--mode", "3d", "--directions", "12", "--offsets", "1", "--angles", "1", "--attempts", "1",
                 "--probes", "1", "--fingers", "2", "--pokes", "2"]}


@pytest.mark.parametrize("mode", ["planar", "3d"])
def test_cli_and_api_give_the_same_estimate(tmp_path, capsys, small_arm, mode):
    """``explore3d run`` and ``explore3d.run`` with the same configuration: the same numbers (the
    command line also records the trajectories for its quality figures: recording changes nothing)."""
    from explore3d import ExploreConfig
    from explore3d import run as api_run
    from explore3d.strategy.active import ProbeConfig

    out = tmp_path / "o"
    code, _, err = run(capsys, "run", "l_block", "--out", str(out), "--arm", str(small_arm), *_FAST[mode],
                       "--a", "0.1", "--seed", "3", "--no-pictures", "-q")
    assert code == 0, err
    report = json.loads((out / "report.json").read_text())
    kw = ({"directions": 24, "offsets": 1, "angles": 1, "attempts": 1,
           "probes": ProbeConfig(rounds=1, fingers=2, pokes=2)} if mode == "3d"
          else {"directions": 3})
    res = api_run(load_object("l_block"), str(small_arm), ExploreConfig(mode=mode, **kw), a=0.1, seed=3)
    assert (report["n_points"], report["n_points_used"]) == (len(res.exploration.points), res.n_points_used)
    for key, value in [("percent_error", res.error.percent), ("iou", res.error.iou),
                       ("chamfer_m", res.error.chamfer_m), ("hausdorff_m", res.error.hausdorff_m),
                       ("true_size", res.error.true_size), ("estimate_size", res.error.estimate_size)]:
        assert report[key] == value, key
    np.testing.assert_array_equal(report["config"]["centre_m"], res.centre)
    assert report["config"]["radius_m"] == res.radius
    assert [(r["wraps"], r["stake_m3"]) for r in report["probe_rounds"]] == \
        [(r["wraps"], r["stake_m3"]) for r in res.exploration.probe_rounds]
    assert len(report["probe_rounds"]) == (1 if mode == "3d" else 0)
    if mode == "planar":
        ring = np.array(json.loads((out / "estimate_polygon.json").read_text()))
        np.testing.assert_array_equal(ring, np.asarray(res.estimate.exterior.coords)[:-1])


ALL_OBJECTS = [*builtin_object_names(), "pybullet_data:duck_vhacd.obj"]


@pytest.mark.parametrize("mode", ["planar", "3d"])
@pytest.mark.parametrize("obj", ALL_OBJECTS)
def test_run_every_object(tmp_path, capsys, small_arm, obj, mode):
    """A fast run on each object: a report with finite errors against the right truth, an estimate
    mesh that loads as a closed volume, inside the robot's rough bound."""
    from explore3d import rough_bound
    from explore3d.app.pipeline import planar_truth

    size = ["--size", "0.1"] if obj.startswith("pybullet_data:") else []
    out = tmp_path / "o"
    code, _, err = run(capsys, "run", obj, *size, "--out", str(out), "--arm", str(small_arm), *_EVERY[mode],
                       "--no-pictures", "--no-quality", "-q")
    assert code == 0, err
    report = json.loads((out / "report.json").read_text())
    assert math.isfinite(report["percent_error"]) and report["percent_error"] >= 0
    assert 0 < report["iou"] <= 1 and report["n_contacts"] > 0
    assert 0 < report["n_points_used"] <= report["n_points"]
    ch = report["estimate_convex_hull"]  # the estimate's convex hull contains it
    assert ch["size"] >= report["estimate_size"] * (1 - 1e-9) and len(ch["centre_m"]) == (2 if mode == "planar" else 3)

    mesh = load_object(obj, size=0.1 if size else None)
    c, radius = rough_bound(mesh.vertices)
    np.testing.assert_allclose(report["config"]["centre_m"], c, rtol=0, atol=1e-15)
    if mode == "planar":  # the truth is the section through the rough centre (tests/test_pipeline.py)
        truth_size = planar_truth(mesh, c[2]).area
    else:
        truth_size = mesh.volume
    assert report["true_size"] == pytest.approx(truth_size, rel=1e-9)

    est = trimesh.load(str(out / "estimate.obj"))
    assert isinstance(est, trimesh.Trimesh) and est.is_watertight and est.volume > 0
    if mode == "planar":
        ring = np.array(json.loads((out / "estimate_polygon.json").read_text()))
        assert np.linalg.norm(ring - c[:2], axis=1).max() <= radius * (1 + 1e-12)
        assert est.volume == pytest.approx(report["estimate_size"] * report["config"]["arm"]["link_height"], rel=1e-5)
    else:
        assert np.linalg.norm(est.vertices - c, axis=1).max() <= radius + 1e-7  # OBJ keeps 8 decimals
        assert est.volume == pytest.approx(report["estimate_size"], rel=1e-5)


# --- the real entry point (one subprocess each; C-level output included) ----------------------------

def _python(*code_or_args):
    import os
    import subprocess

    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    # the timeout only guards against a hang (no speed is asserted here): `table1 --json` took 58 s
    # with the suite on both cores and other work beside it, and timed out at 60 s once
    return subprocess.run([sys.executable, *code_or_args], capture_output=True, text=True, env=env, timeout=600)


HEAVY = ("numpy", "scipy", "trimesh", "shapely", "pybullet", "matplotlib", "tqdm")


@pytest.mark.parametrize("argv", [["-m", "explore3d", "--help"], ["-m", "explore3d", "run", "--help"],
                                  # what the installed console script does
                                  ["-c", "import sys; from explore3d.app.cli import main; sys.exit(main(['run', '--help']))"]])
def test_help_imports_no_heavy_modules(argv):
    """``explore3d --help`` and ``explore3d run --help`` import none of the heavy dependencies
    (read from ``python -X importtime``, which lists every module the process imported)."""
    r = _python("-X", "importtime", *argv)
    assert r.returncode == 0, r.stderr
    assert "usage: explore3d" in r.stdout
    imported = {line.split("|")[-1].strip().split(".")[0] for line in r.stderr.splitlines() if "|" in line}
    assert "explore3d" in imported and "argparse" in imported  # the listing works
    assert sorted(imported & set(HEAVY)) == []


def test_public_names_are_lazy():
    """``import explore3d`` is light; each public name loads on first use, ``explore`` stays the function
    even after its submodule is imported, and ``dir``/``__all__`` list every name."""
    code = ("import sys, explore3d; light = sorted(m for m in %r if m in sys.modules); "
            "import explore3d.strategy.explore, explore3d.world.explore; from explore3d import explore, run, __all__; "
            "import explore3d as e; "
            "print(light, callable(explore) and explore.__module__, run.__module__, "
            "all(n in dir(e) and getattr(e, n) is not None for n in __all__))" % (HEAVY,))
    r = _python("-c", code)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["[]", "explore3d.world.explore", "explore3d.app.pipeline", "True"]
    r = _python("-c", "import explore3d; explore3d.nonesuch")
    assert r.returncode == 1 and "has no attribute 'nonesuch'" in r.stderr


def test_module_entry_point_usage_error(tmp_path):
    r = _python("-m", "explore3d", "run", "cube", "--out", str(tmp_path / "o"), "--a", "0")
    assert r.returncode == 2
    assert_one_line_error(r.stderr, "> 0")


def test_run_calibrate_applies_the_ball_calibration(tmp_path, capsys, small_arm):
    """--calibrate measures the contact thickness on the known ball with the same settings and
    runs with it: the report carries the calibration and the offset actually used; the estimate
    shrinks against the uncalibrated run of the same joint angles."""
    common = ["run", "cube", "--arm", str(small_arm), "--mode", "planar", "--directions", "3", "--attempts", "1",
              "--points", "links", "--no-pictures", "-q", "--jobs", "1"]
    assert run(capsys, *common, "--out", str(tmp_path / "raw"))[0] == 0
    code, _, err = run(capsys, *common, "--out", str(tmp_path / "cal"), "--calibrate")
    assert code == 0, err
    raw = json.loads((tmp_path / "raw" / "report.json").read_text())
    cal = json.loads((tmp_path / "cal" / "report.json").read_text())
    off = cal["calibration"]["face_offset_m"]
    assert 0 < off < 0.002 and cal["calibration"]["n_points"] > 0
    assert cal["config"]["explore"]["face_offset"] == off and raw["config"]["explore"]["face_offset"] == 0.0
    assert cal["n_contacts"] == raw["n_contacts"]  # the offset moves points, not the arm
    assert cal["estimate_size"] < raw["estimate_size"]


def test_run_calibrate_and_face_offset_exclude_each_other(tmp_path, capsys):
    code, _, err = run(capsys, "run", "cube", "--out", str(tmp_path / "o"), "--calibrate", "--face-offset", "0.001")
    assert code == 2
    assert_one_line_error(err, "--calibrate")


# --- issue 9: outputs a user can load and trust ------------------------------------------------------

def test_quality_figures_are_opt_in(tmp_path, capsys, small_arm):
    """Without --quality: no contact-quality figures, no recorded trajectories, no quality time;
    --no-quality (the default) is still accepted; --quality and --no-quality exclude each other."""
    common = ["run", "cube", "--arm", str(small_arm), "--mode", "planar", "--directions", "3", "--attempts", "1", "--points", "links",
              "--no-pictures", "-q"]
    for extra in ([], ["--no-quality"]):
        out = tmp_path / f"o{len(extra)}"
        code, _, err = run(capsys, *common, "--out", str(out), *extra)
        assert code == 0, err
        report = json.loads((out / "report.json").read_text())
        assert "contact_quality" not in report and "quality_s" not in report["timings"]
        assert report["config"]["quality"] is False and report["config"]["explore"]["record"] is False
        assert set(report["timings"]) == {"band_s", "explore_s", "run_s", "write_s", "total_s"}
    code, _, err = run(capsys, *common, "--out", str(tmp_path / "x"), "--quality", "--no-quality")
    assert code == 2
    assert_one_line_error(err, "--no-quality")


def test_default_a_is_one_value_outside_the_paper_replica():
    """One default coarseness (explore3d.core.defaults.DEFAULT_A) everywhere; the paper's 0.2 only in its replica."""
    import importlib.util
    import inspect

    from explore3d.geometry import hull
    from explore3d.app import pipeline, report
    from explore3d.world import simulated
    from explore3d.app import table1
    from explore3d.app.settings import RUN_DEFAULTS
    from explore3d.core.defaults import DEFAULT_A, PAPER_A

    def default(f):
        return inspect.signature(f).parameters["a"].default

    for f in (pipeline.run, report.run_and_report, pipeline.reconstruct_exploration, pipeline.reconstruct_points,
              hull.inverse_hull, hull.invert_points, table1.table3d_rows):
        assert default(f) == DEFAULT_A, f.__name__
    assert RUN_DEFAULTS["a"] == DEFAULT_A
    assert build_parser().parse_args(["reconstruct", "p.ply", "--out", "m.obj"]).a == DEFAULT_A
    spec = importlib.util.spec_from_file_location("explore_mesh", Path(__file__).parents[1] / "scripts" / "explore_mesh.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    assert script.options("x").parse_args([]).a == DEFAULT_A
    assert default(table1.table1_rows) == PAPER_A and default(simulated.simulated_case) == PAPER_A
    assert (DEFAULT_A, PAPER_A) == (0.05, 0.2)


@pytest.mark.parametrize("points", ["contacts", "links"])
def test_reconstruct_builds_the_hull_input_as_run_does(tmp_path, capsys, small_arm, points):
    """``explore3d reconstruct`` on a run's points.ply with the run's rough bound and a gives the run's
    estimate: the same rough-bound cut and the same angular outlier filter over the wrap ids in the
    file.  (The star-prism run with link points has outliers among its points within the rough
    bound, so the comparison can tell; localised contacts are stored at their resolved heights.)"""
    from explore3d.app.export import CONTACT_PROPERTIES, read_points_ply
    from explore3d.reconstruction.hull_input import within_bound

    out = tmp_path / "o"
    # without probes: their wraps leave the link points no outlier to drop (measured), and the
    # comparison needs one
    code, _, err = run(capsys, "run", "star_prism", "--out", str(out), "--arm", str(small_arm), *_SWEEPS_3D,
                       "--probes", "0", "--points", points, "--no-pictures", "-q")
    assert code == 0, err
    report = json.loads((out / "report.json").read_text())
    pts, props = read_points_ply(out / "points.ply", with_properties=True)
    n_bound = int(within_bound(pts, report["config"]["centre_m"], report["config"]["radius_m"]).sum())
    if points == "links":
        assert report["n_points_used"] < n_bound  # the filter dropped points: the comparison can tell
        assert not set(CONTACT_PROPERTIES) & set(props)
    else:
        assert set(CONTACT_PROPERTIES) <= set(props) and report["n_points_used"] <= n_bound
        n = np.stack([props["nx"], props["ny"], props["nz"]], axis=1)
        np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-9)
        assert np.all(props["force_n"] > 0) and np.all(props["uncertainty_m"] <= 0.5e-3)
        # each point lies on its face segment across the link's height (float32 coordinates)
        s0 = np.stack([props["seg0_x"], props["seg0_y"], props["seg0_z"]], axis=1)
        s1 = np.stack([props["seg1_x"], props["seg1_y"], props["seg1_z"]], axis=1)
        t = np.einsum("ij,ij->i", pts - s0, s1 - s0) / np.einsum("ij,ij->i", s1 - s0, s1 - s0)
        assert np.all((t > -1e-4) & (t < 1 + 1e-4))
        np.testing.assert_allclose(s0 + t[:, None] * (s1 - s0), pts, atol=1e-6)
    centre = ",".join(repr(x) for x in report["config"]["centre_m"])
    code, _, err = run(capsys, "reconstruct", str(out / "points.ply"), "--out", str(tmp_path / "re.obj"),
                       "--a", repr(report["a"]), "--centre", centre, "--radius", repr(report["config"]["radius_m"]),
                       "--free-space", str(out / "free_space.npz"))
    assert code == 0, err
    again, est = trimesh.load(str(tmp_path / "re.obj")), trimesh.load(str(out / "estimate.obj"))
    assert len(again.vertices) == len(est.vertices) and len(again.faces) == len(est.faces)
    np.testing.assert_allclose(np.sort(again.vertices, axis=0), np.sort(est.vertices, axis=0), atol=1e-7)  # float32 points.ply
    assert again.volume == pytest.approx(report["estimate_size"], rel=1e-5)


def _tall_box(path, height):
    trimesh.creation.box((0.08, 0.08, height)).export(str(path))
    return path


def test_planar_extrusion_is_what_the_arm_sensed_not_the_true_height(tmp_path, capsys, small_arm):
    """Planar runs on an 80 mm and a 200 mm tall box: the exported estimate spans the arm's plane +-
    half a link height in both (the true height never leaks into it); --height H spans H."""
    from explore3d.arm.urdf import load_arm

    h = load_arm(str(small_arm)).link_height
    common = ["--arm", str(small_arm), "--mode", "planar", "--directions", "3", "--no-pictures", "-q"]
    for height in (0.08, 0.2):
        obj = _tall_box(tmp_path / f"box{height}.stl", height)
        out = tmp_path / f"o{height}"
        code, _, err = run(capsys, "run", str(obj), "--out", str(out), *common)
        assert code == 0, err
        m = trimesh.load(str(out / "estimate.obj"))
        np.testing.assert_allclose(m.bounds[:, 2], [-h / 2, h / 2], atol=1e-7)
    out = tmp_path / "given"
    code, _, err = run(capsys, "run", str(obj), "--out", str(out), *common, "--height", "0.05")
    assert code == 0, err
    report = json.loads((out / "report.json").read_text())
    m = trimesh.load(str(out / "estimate.obj"))
    np.testing.assert_allclose(m.bounds[:, 2], [-0.025, 0.025], atol=1e-7)
    assert report["config"]["height_m"] == 0.05 and m.volume == pytest.approx(0.05 * report["estimate_size"], rel=1e-5)
    code, _, err = run(capsys, "run", str(obj), "--out", str(out), *common, "--height", "0")
    assert code == 2
    assert_one_line_error(err, "--height")


def test_table1_json_has_no_pybullet_banner():
    """The real ``explore3d table1 --json`` (about 8 s): stdout is exactly the JSON, and PyBullet's
    C-level banners reach neither stream."""
    from explore3d.core.quiet import PYBULLET_BANNERS

    r = _python("-m", "explore3d", "table1", "--json")
    assert r.returncode == 0, r.stderr
    rows = json.loads(r.stdout)
    assert len(rows) >= 5 and all("percent" in row for row in rows)
    for banner in PYBULLET_BANNERS:
        assert banner not in r.stdout and banner not in r.stderr, banner
    assert r.stderr == ""


def test_run_prints_one_line_and_no_banner(tmp_path, small_arm):
    """The real entry point of ``run`` (progress bar off): one result line on stdout, nothing on stderr."""
    from explore3d.core.quiet import PYBULLET_BANNERS

    r = _python("-m", "explore3d", "run", "cube", "--out", str(tmp_path / "o"), "--arm", str(small_arm),
                *_FAST["planar"], "--no-pictures", "-q")
    assert r.returncode == 0, r.stderr
    assert r.stderr == "" and r.stdout == ""  # -q: nothing at all
    r = _python("-m", "explore3d", "run", "cube", "--out", str(tmp_path / "o"), "--arm", str(small_arm),
                *_FAST["planar"], "--no-pictures")
    assert r.returncode == 0, r.stderr
    assert len(r.stdout.splitlines()) == 1 and r.stdout.startswith("cube: ")
    for banner in PYBULLET_BANNERS:
        assert banner not in r.stdout and banner not in r.stderr, banner


def test_sensing_and_contact_margin_options_reach_the_report(tmp_path, capsys, small_arm):
    out = tmp_path / "o"
    code, _, err = run(capsys, "run", "cube", "--arm", str(small_arm), "--mode", "planar", "--directions", "3",
                       "--attempts", "1", "--no-pictures", "-q", "--out", str(out), "--sensing", "ideal",
                       "--collision-margin", "0.0005")
    assert code == 0, err
    report = json.loads((out / "report.json").read_text())
    sensors = report["config"]["explore"]["sensors"]
    assert sensors["encoder_counts_per_turn"] == 0 and sensors["delay_steps"] == 0 and sensors["torque_noise_nm"] == 0
    assert report["config"]["explore"]["sim"]["collision_margin"] == 0.0005
    for bad, word in ((["--sensing", "perfect"], "sensing"), (["--collision-margin", "-1"], "--collision-margin"),
                      (["--collision-margin", "0.5"], "collision_margin")):
        code, _, err = run(capsys, "run", "cube", "--out", str(tmp_path / "x"), *bad)
        assert code == 2
        assert_one_line_error(err, word)


def test_scene_option_maps_to_the_table_scene_config():
    from explore3d.app.settings import explore_config
    from explore3d.world.scene import scene_explore_config

    cfg = explore_config({"scene": "table"})
    assert cfg.scene == scene_explore_config("table").scene and cfg.sim.mass_error == 0.05
    assert explore_config({"scene": "ideal"}).scene.ideal
    with pytest.raises(Exception, match="scene"):
        explore_config({"scene": "table", "mode": "planar"})
