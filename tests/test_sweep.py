"""Tests of explore3d.app.sweep and explore3d.app.sweep_report (``explore3d sweep``, ``explore3d sweep-report``).

The simulated sweeps use the small 16-link arm in planar mode (3 directions: a few seconds a run):
2 objects (a built-in and a mesh file found by a glob) x 2 values of ``a``."""
import hashlib
import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh

from explore3d.app.cli import main
from explore3d.app.sweep import DB_NAME, SWEEP_KEYS, TIMING_COLUMNS, RunTask, execute, mesh_sha256, parse_grid, read_grid_file, read_rows, resolve_objects, run_sweep, settings_grid, sweep_tasks

ROOT = Path(__file__).resolve().parents[1]
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _without_timings(rows):
    return [{k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in rows]


def _one_line(err):
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("explore3d: error: ") and "Traceback" not in err, err
    return lines[0]


# --- settings, objects, keys (no simulation) ----------------------------------------------------

def test_parse_grid_checks_values_as_run_does():
    g = parse_grid(["a=0.02,0.05", "arm=default,paper", "probes=0,1", "mirrored=true", "sensing=ideal"])
    assert g == {"a": [0.02, 0.05], "arm": ["default", "paper"], "probes": [0, 1], "mirrored": [True],
                 "sensing": ["ideal"]}
    with pytest.raises(ValueError, match="unknown sweep setting 'bogus'; valid keys: a, angles, arm") as e:
        parse_grid(["bogus=1"])
    assert "\n" not in str(e.value)
    for bad, words in ((["a=-1"], "> 0"), (["directions=2.5"], "integer"), (["mode=sideways"], "planar"),
                       (["a"], "KEY=V1,V2"), (["a="], "no values"), (["a=1", "a=2"], "twice")):
        with pytest.raises(ValueError, match=words):
            parse_grid(bad)


def test_grid_file(tmp_path):
    path = tmp_path / "sweep.toml"
    path.write_text('a = [0.02, 0.05]\narm = "paper"\nmode = "planar"\ndirections = [2, 3]\n')
    assert read_grid_file(path) == {"a": [0.02, 0.05], "arm": ["paper"], "mode": ["planar"], "directions": [2, 3]}
    path.write_text("wraps = 3\n")
    with pytest.raises(ValueError, match="valid keys"):
        read_grid_file(path)
    path.write_text("a = [\n")
    with pytest.raises(ValueError, match="not valid TOML"):
        read_grid_file(path)
    with pytest.raises(ValueError, match="not found"):
        read_grid_file(tmp_path / "missing.toml")


def test_settings_hash_is_canonical():
    combos = settings_grid({"a": [0.05, 0.1], "arm": ["default", "paper"]})
    assert combos == [{"a": 0.05, "arm": "default"}, {"a": 0.05, "arm": "paper"}, {"a": 0.1, "arm": "default"},
                      {"a": 0.1, "arm": "paper"}]
    assert settings_grid({"mode": ["3d", "3d"]}) == [{"mode": "3d"}]
    t = RunTask("cube", "h", {"arm": "paper", "a": 0.1})
    # key order does not matter; a default value is the same as none; seed is its own part of the key
    assert t.settings_sha256 == RunTask("cube", "h", {"a": 0.1, "arm": "paper", "mode": "3d"}).settings_sha256
    assert t.settings_sha256 == RunTask("cube", "h", {"a": 0.1, "arm": "paper", "seed": 4}).settings_sha256
    assert t.settings_json == '{"a":0.1,"arm":"paper"}'
    assert t.settings_sha256 == hashlib.sha256(b'{"a":0.1,"arm":"paper"}').hexdigest()
    keys = {t.key, RunTask("cube", "h", {"arm": "paper", "a": 0.1}, seed=1).key,
            RunTask("cube", "h2", {"arm": "paper", "a": 0.1}).key, RunTask("cube", "h", {"a": 0.1}).key,
            RunTask("cube", "h", {"arm": "paper", "a": 0.1}, version="9").key}
    assert len(keys) == 5


def test_resolve_objects(tmp_path):
    for name in ("b.stl", "a.stl"):
        trimesh.creation.box([0.05, 0.04, 0.03]).export(tmp_path / name)
    found = resolve_objects(["cube", str(tmp_path / "*.stl"), "cube", "pybullet_data:toys/c*.obj"])
    assert found == ["cube", str(tmp_path / "a.stl"), str(tmp_path / "b.stl"), "pybullet_data:toys/concave_box.obj",
                     "pybullet_data:toys/cube.obj", "pybullet_data:toys/cylinder.obj"]
    assert mesh_sha256(str(tmp_path / "a.stl")) == hashlib.sha256((tmp_path / "a.stl").read_bytes()).hexdigest()
    assert mesh_sha256("cube") == mesh_sha256("cube") != mesh_sha256("sphere")
    for spec, words in (("no_such_shape", "unknown object"), (str(tmp_path / "*.ply"), "no file matches"),
                        ("pybullet_data:toys/*.xyz", "no file in pybullet_data"),
                        (str(tmp_path / "gone.stl"), "not found")):
        with pytest.raises(ValueError, match=words):
            resolve_objects([spec])


def test_sweep_tasks_apply_size_and_check_arms():
    tasks = sweep_tasks(["cube", "sphere"], {"a": [0.05, 0.1]}, size=0.05)
    assert [(t.object, t.settings) for t in tasks] == [
        ("cube", {"a": 0.05, "size": 0.05}), ("cube", {"a": 0.1, "size": 0.05}),
        ("sphere", {"a": 0.05, "size": 0.05}), ("sphere", {"a": 0.1, "size": 0.05})]
    with pytest.raises(ValueError, match="arm"):
        sweep_tasks(["cube"], {"arm": ["octopus"]})


def test_a_failing_run_is_a_result(monkeypatch):
    monkeypatch.setenv("EXPLORE3D_SWEEP_FAULT", "raise:cube")
    m = trimesh.creation.box([0.08] * 3)
    out = execute(RunTask("cube", "h", {}), m.vertices, m.faces)
    assert out["status"] == "failed"
    assert out["reason"].startswith("RuntimeError: injected failure") and "\n" not in out["reason"]


def test_cli_sweep_usage_errors(tmp_path, capsys):
    for cmd in ("sweep", "sweep-report"):
        assert main([cmd, "--help"]) == 0
        assert f"usage: explore3d {cmd}" in capsys.readouterr().out
    assert main(["sweep", "cube", "--out", str(tmp_path / "s"), "--grid", "wraps=3"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "unknown sweep setting 'wraps'" in line and all(k in line for k in SWEEP_KEYS)
    assert main(["sweep", "no_such_shape", "--out", str(tmp_path / "s")]) == 2
    assert "unknown object" in _one_line(capsys.readouterr().err)
    assert main(["sweep-report", str(tmp_path)]) == 1
    assert "holds no sweep.db" in _one_line(capsys.readouterr().err)
    assert not (tmp_path / "s").exists()  # nothing written before the input is checked


# --- simulated sweeps ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    """The small arm, a box file, the grid, and the contact band measured once (the runs read it)."""
    from explore3d import ArmSpec, ExploreConfig, cached_band, write_arm_urdf

    d = tmp_path_factory.mktemp("sweep")
    spec = ArmSpec(name="small16", n_links=16, link_length=0.02)
    arm = str(write_arm_urdf(spec, d / "small16.urdf"))
    (d / "objs").mkdir()
    trimesh.creation.box([0.07, 0.05, 0.06]).export(d / "objs" / "box.stl")
    cfg = ExploreConfig(mode="planar")
    cached_band(spec, cfg.control, cfg.sim, cfg.sensors, True)
    grid = {"a": [0.05, 0.1], "mode": ["planar"], "directions": [3], "arm": [arm]}
    objects = ["cube", str(d / "objs" / "*.stl")]
    argv_grid = ["--grid", "mode=planar", "--grid", "directions=3", "--grid", f"arm={arm}"]  # + a test's own --grid a=...
    return {"dir": d, "arm": arm, "grid": grid, "objects": objects, "argv": [*objects, *argv_grid],
            "box": str((d / "objs" / "box.stl").resolve())}


@pytest.fixture(scope="module")
def reference(setup):
    """The uninterrupted sweep on local processes, 2 at once."""
    out = setup["dir"] / "reference"
    t0 = time.perf_counter()
    s = run_sweep(setup["objects"], out, setup["grid"], workers=2, progress=False)
    return {"dir": out, "summary": s, "rows": read_rows(out), "wall_s": time.perf_counter() - t0}


def test_local_sweep_stores_every_combination(setup, reference):
    s, rows, out = reference["summary"], reference["rows"], reference["dir"]
    assert (s.total, s.stored_before, s.ran, s.ok, s.failed) == (4, 0, 4, 4, 0)
    assert [r["object"] for r in rows] == [setup["box"], setup["box"], "cube", "cube"]  # sorted by object
    assert [json.loads(r["settings"])["a"] for r in rows] == [0.05, 0.1, 0.05, 0.1]
    assert len({r["key"] for r in rows}) == 4 and {r["status"] for r in rows} == {"ok"}
    for r in rows:
        assert 0 <= r["percent_error"] < 30 and 0 < r["iou"] <= 1 and r["chamfer_m"] > 0 and r["time_s"] > 0
        report = json.loads(r["report"])
        assert report["mode"] == "planar" and "timings" not in report and "wall_s" not in report
        assert set(json.loads(r["timings"])) == {"timings", "wall_s"}
        est = trimesh.load_mesh(out / r["run_dir"] / "estimate.stl")
        assert est.is_watertight and est.volume > 0
        assert (out / r["run_dir"] / "estimate_polygon.json").is_file()
        assert (out / r["truth"]).is_file()
        assert r["version"] and r["seed"] == 0 and len(r["mesh_sha256"]) == 64
    mode = sqlite3.connect(out / DB_NAME).execute("PRAGMA journal_mode").fetchone()[0]
    assert mode == "wal"
    # the same command again runs nothing and changes nothing
    again = run_sweep(setup["objects"], out, setup["grid"], workers=2, progress=False)
    assert (again.ran, again.stored_before) == (0, 4)
    assert read_rows(out) == rows


def test_ray_sweep_rows_equal_local(setup, reference, tmp_path):
    ray = pytest.importorskip("ray", reason="ray is not installed: pip install -e '.[ray]' (the 'all' extra has it)")
    assert not ray.is_initialized()
    s = run_sweep(setup["objects"], tmp_path / "ray", setup["grid"], workers=2, backend="ray", progress=False)
    assert (s.ran, s.ok) == (4, 4)
    assert not ray.is_initialized()  # the Ray started on demand is shut down
    assert _without_timings(read_rows(tmp_path / "ray")) == _without_timings(reference["rows"])


def test_killed_sweep_rerun_loses_nothing(setup, reference, tmp_path, capsys):
    out = tmp_path / "killed"
    argv = ["sweep", *setup["argv"], "--out", str(out), "--grid", "a=0.05", "-q"]  # 2 runs, one at a time
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-m", "explore3d", *argv], env=env, start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 90
        n = 0
        while n == 0 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
            if (out / DB_NAME).is_file():
                try:
                    n = sqlite3.connect(out / DB_NAME, timeout=5).execute("SELECT COUNT(*) FROM runs").fetchone()[0]
                except sqlite3.OperationalError:  # the table is not created yet
                    n = 0
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)  # the sweep and the runs it started (its own session)
        except ProcessLookupError:  # it had finished: the assertion below says so
            pass
        proc.wait()
    # the killed sweep's lock released, not only its main process reaped: a child caught between
    # fork and exec holds the lock's file until it dies too, and on loaded cores that can be after
    # proc.wait() returned (a fresh-clone .ci/run was refused "another sweep is running")
    import fcntl

    deadline = time.monotonic() + 60
    fd = os.open(out / "sweep.lock", os.O_RDWR)
    try:
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                fcntl.flock(fd, fcntl.LOCK_UN)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    pytest.fail("the killed sweep's lock was still held 60 s after SIGKILL")
                time.sleep(0.05)
    finally:
        os.close(fd)
    before = read_rows(out)
    assert len(before) == 1, "the sweep was not killed part-way"
    assert main(argv) == 0
    after = read_rows(out)
    assert len(after) == 2
    ref = {r["key"]: r for r in _without_timings(reference["rows"])}
    assert _without_timings(after) == [ref[r["key"]] for r in after]
    kept = {r["key"]: r for r in after}
    assert all(kept[r["key"]] == r for r in before)  # rows stored before the kill are untouched (timings too)


def test_crashing_worker_is_stored_and_the_sweep_goes_on(setup, reference, tmp_path, monkeypatch):
    out = tmp_path / "crash"
    grid = {**setup["grid"], "a": [0.05]}
    monkeypatch.setenv("EXPLORE3D_SWEEP_FAULT", "segfault:cube")
    s = run_sweep(setup["objects"], out, grid, progress=False)
    assert (s.ran, s.ok, s.failed) == (2, 1, 1)
    rows = {r["object"]: r for r in read_rows(out)}
    assert rows["cube"]["status"] == "failed" and "SIGSEGV" in rows["cube"]["reason"]
    assert "\n" not in rows["cube"]["reason"] and rows["cube"]["percent_error"] is None
    assert rows[setup["box"]]["status"] == "ok"
    monkeypatch.delenv("EXPLORE3D_SWEEP_FAULT")
    assert run_sweep(setup["objects"], out, grid, progress=False).ran == 0  # failures are results
    s = run_sweep(setup["objects"], out, grid, retry_failed=True, progress=False)
    assert (s.ran, s.ok) == (1, 1)
    ref = {r["key"]: r for r in _without_timings(reference["rows"])}
    assert all(ref[r["key"]] == r for r in _without_timings(read_rows(out)))


def test_sweep_report(reference, tmp_path, capsys):
    out = tmp_path / "report"
    assert main(["sweep-report", str(reference["dir"]), "--out", str(out)]) == 0
    md = (out / "report.md").read_text()
    assert "| object | a | status | error_percent | iou | chamfer_mm | time_s | reason | key |" in md
    assert md.split("## Per object and setting")[1].count("| ok |") == 4
    lines = (out / "report.csv").read_text().splitlines()
    assert lines[0] == "object,a,status,error_percent,iou,chamfer_mm,time_s,reason,key" and len(lines) == 5
    for r, line in zip(reference["rows"], lines[1:]):
        assert float(line.split(",")[3]) == r["percent_error"]
    html = (out / "report.html").read_text()
    for r in reference["rows"]:
        png = out / "thumbs" / f"{r['key']}.png"
        assert f"thumbs/{r['key']}.png" in html and png.read_bytes().startswith(PNG_MAGIC)
    assert (out / "errors.png").read_bytes().startswith(PNG_MAGIC) and "errors.png" in html


# --- the signed-distance picture ----------------------------------------------------------------

def test_signed_distance_sign_and_figure(tmp_path):
    from explore3d.world.objects import load_object, square
    from explore3d.app.pictures import signed_distance_figure, signed_distance_mm

    cube = load_object("cube")  # 80 mm
    big, small = cube.copy(), cube.copy()
    big.apply_scale(1.1)
    small.apply_scale(0.9)
    # the cube's vertices are its corners: 4 sqrt(3) mm outside the truth's corner, 4 mm inside its faces
    np.testing.assert_allclose(signed_distance_mm(big, cube), 4.0 * 3 ** 0.5, atol=1e-4)
    np.testing.assert_allclose(signed_distance_mm(small, cube), -4.0, atol=1e-4)
    sd = signed_distance_mm(square(0.088), square(0.08))
    assert sd.min() == pytest.approx(4.0, abs=1e-9) and sd.max() == pytest.approx(4.0 * 2 ** 0.5, abs=1e-9)
    for est, truth, name in ((big, cube, "sd.png"), (square(0.07), square(0.08), "sd2.png")):
        signed_distance_figure(est, truth, tmp_path / name)
        assert (tmp_path / name).read_bytes().startswith(PNG_MAGIC)
