"""Bad input, tried as a new user would: every case exits 1 or 2 with one line on stderr naming
the problem, no traceback, and nothing written (issue 21).  The command line runs in-process
(``explore3d.app.cli.main``); the public API raises ValueError/TypeError (or the library's own
subclasses) with a message naming the fix.  None of these cases explores: each must be refused
before the simulation starts."""
import math
from pathlib import Path

import numpy as np
import pytest
import trimesh
from test_sweep_robust import _as_reader, shared_dir  # noqa: F401 (shared_dir: a fixture)

from explore3d.app.cli import main


def run_cli(capsys, argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line(err, word):
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("explore3d: error: "), lines[0]
    assert "Traceback" not in err
    assert word.lower() in lines[0].lower(), lines[0]


# --- files the cases use (made in each test's own folder) --------------------------------------------

def _nan_obj(d: Path, value="nan") -> Path:
    m = trimesh.creation.box((0.05, 0.05, 0.05))
    text = m.export(file_type="obj")
    lines = text.splitlines()
    first = next(i for i, ln in enumerate(lines) if ln.startswith("v "))
    lines[first] = f"v {value} 0.025 0.025"
    (d / "nan.obj").write_text("\n".join(lines) + "\n")
    return d / "nan.obj"


def _open_mesh(d: Path) -> Path:
    m = trimesh.creation.cylinder(radius=0.03, height=0.05, sections=32)
    trimesh.Trimesh(m.vertices, m.faces[m.face_normals[:, 2] < 0.9], process=False).export(str(d / "open.stl"))
    return d / "open.stl"


def _huge_mesh(d: Path) -> Path:
    trimesh.creation.icosphere(subdivisions=7, radius=0.05).export(str(d / "huge.stl"))  # 327,680 faces
    return d / "huge.stl"


def _points(d: Path, P, name="p.ply", **props) -> Path:
    from explore3d.app.export import write_points_ply

    write_points_ply(np.asarray(P, float), d / name, **props)
    return d / name


def _cloud(d: Path) -> Path:
    return _points(d, np.random.default_rng(0).normal(scale=0.03, size=(60, 3)))


def _text(d: Path, name: str, text: str) -> Path:
    (d / name).write_text(text)
    return d / name


MAKERS = {
    "nan_obj": _nan_obj,
    "inf_obj": lambda d: _nan_obj(d, "inf"),
    "open": _open_mesh,
    "huge": _huge_mesh,
    "notes": lambda d: _text(d, "notes.stl", "this is not a mesh\n"),
    "empty": lambda d: _text(d, "empty.obj", ""),
    "cloud": _cloud,
    "flat3": lambda d: _points(d, [[0, 0, 1], [1, 0, 1], [0, 1, 1]]),
    "two": lambda d: _points(d, [[0, 0, 0], [1, 0, 0]]),
    "planar": lambda d: _points(d, np.column_stack([np.random.default_rng(1).normal(size=(40, 2)), np.zeros(40)])),
    "garbage_ply": lambda d: _text(d, "g.ply", "ply\nthis is not it\n"),
    "bad_toml": lambda d: _text(d, "c.toml", "a = [\n"),
    "toml_unknown": lambda d: _text(d, "c.toml", "wings = 3\n"),
    "toml_bad_value": lambda d: _text(d, "c.toml", "directions = 'many'\n"),
    "bad_urdf": lambda d: _text(d, "arm.urdf", "<robot name='x'><link name='only'/></robot>\n"),
    "not_xml_urdf": lambda d: _text(d, "arm.urdf", "not xml at all\n"),
    "blocker": lambda d: _text(d, "blocker", "a file where a folder should be\n"),
    "bad_polygon": lambda d: _text(d, "poly.json", "[[0, 0], [1, 1]]\n"),
    "not_json": lambda d: _text(d, "poly.json", "{not json\n"),
    "square": lambda d: _text(d, "sq.json", "[[0, 0], [0.05, 0], [0.05, 0.05], [0, 0.05]]\n"),
    "bad_grid_file": lambda d: _text(d, "grid.toml", "a = [0.05,\n"),
}


def _argv(d: Path, argv):
    """``{name}`` in an argument becomes the file MAKERS[name] makes in ``d``; ``@x`` becomes d/x."""
    import re

    out = []
    for a in argv:
        a = re.sub(r"\{(\w+)\}", lambda m: str(MAKERS[m.group(1)](d)), a)
        out.append(str(d / a[1:]) if a.startswith("@") else a)
    return out


#: (argv, exit code, a word the one line must hold).  "@o" is the output folder, which must not
#: be left with any file.
CASES = [
    # run: numbers and choices
    (["run", "cube", "--out", "@o", "--a", "300"], 2, "at most"),
    (["run", "cube", "--out", "@o", "--a", "0"], 2, "> 0"),
    (["run", "cube", "--out", "@o", "--a", "nan"], 2, "finite"),
    (["run", "cube", "--out", "@o", "--a", "inf"], 2, "finite"),
    (["run", "cube", "--out", "@o", "--a", "-0.1"], 2, "> 0"),
    (["run", "cube", "--out", "@o", "--method", "bogus"], 2, "bogus"),
    (["run", "cube", "--out", "@o", "--scale", "-1"], 2, "scale"),
    (["run", "cube", "--out", "@o", "--size", "0"], 2, "size"),
    (["run", "cube", "--out", "@o", "--centre", "1,2"], 2, "x,y,z"),
    (["run", "cube", "--out", "@o", "--centre", "1,2,nan"], 2, "centre"),
    (["run", "cube", "--out", "@o", "--grasp", "-1"], 2, "--grasp must be an integer >= 0"),
    (["run", "cube", "--out", "@o", "--record", "@o"], 2, "the --out folder"),
    (["run", "cube", "--out", "@o", "--rerun", "@o/run.txt"], 2, "ending in .rrd"),
    (["run", "cube", "--out", "@o", "--rerun", "@nowhere/run.rrd"], 1, "does not exist"),
    (["run", "cube", "--out", "@o", "--mode", "planar", "--grasp", "5"], 2, "3D estimate"),
    (["run", "cube", "--out", "@o", "--radius", "-1"], 2, "radius"),
    (["run", "cube", "--out", "@o", "--jobs", "0"], 2, "jobs"),
    (["run", "cube", "--out", "@o", "--directions", "-1"], 2, "directions"),
    (["run", "cube", "--out", "@o", "--attempts", "x"], 2, "attempts"),
    (["run", "cube", "--out", "@o", "--format", "xyz"], 2, "xyz"),
    (["run", "cube", "--out", "@o", "--mode", "4d"], 2, "4d"),
    (["run", "cube", "--out", "@o", "--scene", "moon"], 2, "moon"),
    (["run", "cube", "--out", "@o", "--sensing", "psychic"], 2, "psychic"),
    (["run", "cube", "--out", "@o", "--points", "stars"], 2, "stars"),
    (["run", "cube", "--out", "@o", "--probes", "-1"], 2, "probes"),
    (["run", "cube", "--out", "@o", "--fingers", "x"], 2, "fingers"),
    (["run", "cube", "--out", "@o", "--probe-rank", "far"], 2, "probe_rank"),
    (["run", "cube", "--out", "@o", "--encircle", "spiral"], 2, "spiral"),
    (["run", "cube", "--out", "@o", "--density", "0"], 2, "density"),
    (["run", "cube", "--out", "@o", "--height", "-1"], 2, "height"),
    (["run", "cube", "--out", "@o", "--collision-margin", "-1"], 2, "margin"),
    (["run", "cube", "--out", "@o", "--seed", "1.5"], 2, "seed"),
    (["run", "cube", "--out", "@o", "--calibrate", "--face-offset", "0.001", "--points", "links"], 2, "not allowed"),
    (["run", "cube", "--out", "@o", "--face-offset", "0.001"], 2, "--points links"),
    (["run", "cube", "--out", "@o", "--scale", "1", "--size", "1"], 2, "not allowed"),
    (["run", "cube", "--out", "@o", "--no-such-flag"], 2, "no-such-flag"),
    (["run", "cube"], 2, "--out"),
    # run: the object and the arm
    (["run", "nonesuch", "--out", "@o"], 2, "unknown object"),
    (["run", "pybullet_data:nonesuch.obj", "--out", "@o"], 1, "pybullet_data"),
    (["run", "{notes}", "--out", "@o"], 1, "notes.stl"),
    (["run", "{empty}", "--out", "@o"], 1, "empty.obj"),
    (["run", "{open}", "--out", "@o"], 1, "not a closed volume"),
    (["run", "{nan_obj}", "--out", "@o"], 1, "non-finite"),
    (["run", "{inf_obj}", "--out", "@o"], 1, "non-finite"),
    (["run", "{huge}", "--out", "@o"], 1, "faces"),
    (["run", "cube", "--size", "1000", "--out", "@o"], 1, "arm's length"),
    (["run", "cube", "--size", "1e-6", "--out", "@o"], 1, "link width"),
    (["run", "cube", "--radius", "5", "--centre", "0,0,0", "--out", "@o"], 1, "arm's length"),
    (["run", "cube", "--arm", "octopus", "--out", "@o"], 2, "octopus"),
    (["run", "cube", "--arm", "{bad_urdf}", "--out", "@o"], 2, "arm.urdf"),
    (["run", "cube", "--arm", "{not_xml_urdf}", "--out", "@o"], 2, "arm.urdf"),
    (["run", "--config", "@missing.toml", "--out", "@o"], 2, "missing.toml"),
    (["run", "--config", "{bad_toml}", "--out", "@o"], 2, "c.toml"),
    (["run", "--config", "{toml_unknown}", "--out", "@o"], 2, "wings"),
    (["run", "--config", "{toml_bad_value}", "--out", "@o"], 2, "directions"),
    (["run", "cube", "--out", "{blocker}/sub"], 1, "output folder"),
    # reconstruct
    (["reconstruct", "--log", "@nowhere", "--out", "@o/m.obj"], 1, "holds no recording.json"),
    (["reconstruct", "--out", "@o/m.obj"], 2, "needs a point file"),
    (["reconstruct", "--bag", "@nowhere", "--readings", "--arm", "default", "--out", "@o/m.obj"], 2, "--band FILE"),
    (["reconstruct", "--log", "@nowhere", "--arm", "default", "--out", "@o/m.obj"], 2, "--arm reads another"),
    (["reconstruct", "{cloud}", "--readings", "--out", "@o/m.obj"], 2, "--readings reads a recording"),
    (["reconstruct", "{cloud}", "--log", "@nowhere", "--out", "@o/m.obj"], 2, "drop POINTS"),
    (["reconstruct", "@missing.ply", "--out", "@o/m.obj"], 1, "not found"),
    (["reconstruct", "{garbage_ply}", "--out", "@o/m.obj"], 1, "g.ply"),
    (["reconstruct", "{cloud}", "--out", "@o/m.obj", "--a", "300"], 2, "at most"),
    (["reconstruct", "{cloud}", "--out", "@o/m.obj", "--a", "0"], 2, "> 0"),
    (["reconstruct", "{flat3}", "--out", "@o/m.obj"], 1, "too few"),
    (["reconstruct", "{two}", "--out", "@o/m.obj"], 1, "too few"),
    (["reconstruct", "{cloud}", "--out", "@o/m.dae"], 2, "dae"),
    (["reconstruct", "{cloud}", "--out", "@o/m.obj", "--radius", "0.1"], 2, "--centre"),
    (["reconstruct", "{cloud}", "--out", "@o/m.obj", "--centre", "1,2,3,4"], 2, "centre"),
    (["reconstruct", "{cloud}", "--out", "@o/m.obj", "--centre", "middle"], 2, "centre"),
    (["reconstruct", "{cloud}", "--out", "@o/m.obj", "--estimator", "implicit"], 2, "normals"),
    (["reconstruct", "{cloud}", "--out", "@o/m.obj", "--estimator", "guess"], 2, "guess"),
    (["reconstruct", "{cloud}", "--out", "@o/m.obj", "--free-space", "@none.npz"], 1, "free-space"),
    (["reconstruct", "{planar}", "--out", "@o/m.obj"], 2, "--height"),
    (["reconstruct", "{cloud}", "--out", "@o/m.json"], 2, "mesh file"),
    # evaluate
    (["evaluate", "@missing.stl", "cube"], 1, "not found"),
    (["evaluate", "{open}", "cube"], 1, "not a closed volume"),
    (["evaluate", "{nan_obj}", "cube"], 1, "non-finite"),
    (["evaluate", "{bad_polygon}", "{bad_polygon}"], 1, "poly.json"),
    (["evaluate", "{not_json}", "cube"], 1, "poly.json"),
    (["evaluate", "{square}", "cube"], 1, "2D"),
    # compare, table1, arm, sweep, objects
    (["compare", "nonesuch"], 2, "unknown object"),
    (["compare", "cube", "--a", "300"], 2, "at most"),
    (["compare", "cube", "--size", "1000"], 1, "arm's length"),
    (["table1", "--a", "0"], 2, "> 0"),
    (["table1", "--a", "300"], 2, "at most"),
    (["band", "--out", "@o/band.txt"], 2, "ending in .json"),
    (["band", "--out", "@nowhere/band.json"], 1, "does not exist"),
    (["band", "--log", "@nowhere", "--out", "@o/band.json"], 1, "holds no .npz"),
    (["band", "--arm", "nonesuch", "--out", "@o/band.json"], 2, "unknown arm"),
    (["arm", "--out", "@o/a.urdf", "--n-links", "0"], 2, "n-links"),
    (["arm", "--out", "@o/a.urdf", "--link-length", "-1"], 2, "link-length"),
    (["arm", "--out", "{blocker}/a.urdf"], 1, "blocker"),
    (["sweep", "cube", "--out", "@o", "--grid", "wings=1,2"], 2, "wings"),
    (["sweep", "cube", "--out", "@o", "--grid", "a=300"], 2, "at most"),
    (["sweep", "cube", "--out", "@o", "--grid", "a"], 2, "KEY=V1"),
    (["sweep", "cube", "--out", "@o", "--grid-file", "{bad_grid_file}"], 2, "grid.toml"),
    (["sweep", "cube", "--out", "@o", "--workers", "0"], 2, "workers"),
    (["sweep-report", "@nowhere"], 1, "nowhere"),
    (["objects", "--colour"], 2, "colour"),
    (["grasp", "@nowhere"], 1, "report.json not found"),
    (["grasp", "@o", "--n", "0"], 2, "--n must be an integer >= 1"),
    (["grasp", "@o", "--friction", "0"], 2, "--friction must be > 0"),
    (["teleport"], 2, "teleport"),
]


@pytest.mark.parametrize("argv,code,word", CASES, ids=[" ".join(c[0])[:60] for c in CASES])
def test_command_line_bad_input(tmp_path, capsys, monkeypatch, argv, code, word):
    _no_exploring(monkeypatch)
    got, out, err = run_cli(capsys, _argv(tmp_path, argv))
    assert got == code, err
    assert_one_line(err, word)
    assert "Traceback" not in out
    o = tmp_path / "o"
    assert not o.exists() or not any(p.is_file() for p in o.rglob("*")), sorted(o.rglob("*"))


def test_there_are_at_least_60_cases_over_every_command():
    from explore3d.app.cli import build_parser

    assert len(CASES) >= 60
    sub = next(a for a in build_parser()._actions if a.dest == "command" or getattr(a, "choices", None))
    commands = set(sub.choices)
    assert commands <= {c[0][0] for c in CASES}, commands - {c[0][0] for c in CASES}


# --- the public API -----------------------------------------------------------------------------------

def _cube():
    from explore3d import load_object

    return load_object("cube")


def _nan_cube():
    m = _cube()
    v = m.vertices.copy()
    v[0, 0] = math.nan
    m.vertices = v
    return m


def _api_cases():
    from explore3d import ArmSpec, ExploreConfig, inverse_hull, load_object, run, shape_error
    from shapely.geometry import box

    pts = np.random.default_rng(0).normal(size=(50, 3))
    return [
        (lambda: run(None), TypeError, "trimesh"),
        (lambda: run(_cube(), config={}), TypeError, "ExploreConfig"),
        (lambda: run(_cube(), a=0), ValueError, "a must be"),
        (lambda: run(_cube(), a=300), ValueError, "at most"),
        (lambda: run(_cube(), method="bogus"), ValueError, "method"),
        (lambda: run(_nan_cube()), ValueError, "non-finite"),
        (lambda: run(load_object("cube", size=1000)), ValueError, "arm's length"),
        (lambda: run(load_object("cube", size=1e-6)), ValueError, "link width"),
        (lambda: run(_cube(), arm="octopus"), ValueError, "octopus"),
        (lambda: run(_cube(), centre=(0, 0)), ValueError, "centre"),
        (lambda: run(_cube(), radius=-1), ValueError, "radius"),
        (lambda: run(trimesh.creation.icosphere(subdivisions=7, radius=0.05)), ValueError, "faces"),
        (lambda: load_object("nonesuch"), ValueError, "unknown object"),
        (lambda: load_object("cube", scale=-1), ValueError, "scale"),
        (lambda: load_object("cube", scale=1, size=1), ValueError, "not both"),
        (lambda: inverse_hull(pts, a=300), ValueError, "at most"),
        (lambda: inverse_hull(pts[:3]), ValueError, "at least 4"),
        (lambda: inverse_hull(np.full((10, 3), np.nan)), ValueError, "finite"),
        (lambda: inverse_hull(pts, method="bogus"), ValueError, "method"),
        (lambda: shape_error(box(0, 0, 1, 1), _cube()), ValueError, "2D"),
        (lambda: ExploreConfig(directions=0), ValueError, "directions"),
        (lambda: ArmSpec(n_links=0), ValueError, "n_links"),
    ]


def _no_exploring(monkeypatch):
    """Make any exploration fail the test: every case must be refused before the simulation."""
    import importlib

    def explored(*args, **kwargs):
        raise AssertionError("the bad input reached the exploration")

    for name in ("explore3d.app.pipeline", "explore3d.app.compare", "explore3d.world.explore"):  # each binds `explore`
        monkeypatch.setattr(importlib.import_module(name), "explore", explored)
    monkeypatch.setattr(importlib.import_module("explore3d.world.explore"), "explore_robots", explored)


@pytest.mark.parametrize("i", range(22))
def test_api_bad_input(i, monkeypatch):
    """Each refused before any exploration (run(a=0) and run(method=...) were refused only after
    a whole exploration, with advice to explore more)."""
    _no_exploring(monkeypatch)
    call, kind, word = _api_cases()[i]
    with pytest.raises(kind) as info:
        call()
    assert word.lower() in str(info.value).lower(), str(info.value)
    assert len(str(info.value).splitlines()) == 1


def test_repairs_reach_stderr_and_verbose_logging_works(tmp_path, capsys):
    """A mesh that needs repair says so on stderr even with PyBullet's C output silenced, and -vv
    prints log lines (both went to a stderr pointed at /dev/null)."""
    m = trimesh.creation.box((0.05, 0.05, 0.05))
    m.invert()  # inside out: load_object turns it outward and says so
    m.export(str(tmp_path / "inside_out.stl"))
    code, _, err = run_cli(capsys, ["run", tmp_path / "inside_out.stl", "--out", tmp_path / "o", "--size", "1000",
                                    "-vv"])
    assert code == 1
    assert "repaired" in err and "turned the inside-out surface outward" in err
    assert "DEBUG" in err or "INFO" in err
    assert not (tmp_path / "o" / "report.json").exists()


def test_an_unwritable_output_file_is_named_not_its_hidden_temporary(shared_dir):
    """``reconstruct --out RO/m.obj`` into a folder the user cannot write: one line naming RO/m.obj
    (it named the hidden ``.m.<pid>.<random>.part.obj`` the atomic write makes), exit 1."""
    import subprocess
    import sys

    ro = shared_dir / "ro"
    ro.mkdir()
    cloud = _cloud(shared_dir)
    cloud.chmod(0o644)
    elsewhere = shared_dir / "elsewhere"
    elsewhere.mkdir()
    prefix, kw, restore = _as_reader(ro, elsewhere)
    try:
        r = subprocess.run([*prefix, sys.executable, "-m", "explore3d", "reconstruct", str(cloud), "--out",
                            str(ro / "m.obj")], capture_output=True, text=True, timeout=120, **kw)
    finally:
        restore()
    assert r.returncode == 1, r.stderr
    assert_one_line(r.stderr, "m.obj")
    assert ".part" not in r.stderr and not any(ro.iterdir())
