"""explore3d.run (the pipeline): the robot's rough bound, no-contact and reconstruction failures
without mocks, and the planar truth of multi-body meshes."""
import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from explore3d import ArmSpec, ExploreConfig, NoContactError, ReconstructionError, load_arm, load_object, rough_bound, run
from explore3d.core.quiet import PYBULLET_BANNERS
from explore3d.world.objects import cross_section
from explore3d.app.pipeline import planar_truth
from explore3d.reconstruction.hull_input import within_bound

#: 8 x 20 mm links (reach 0.16 m): a wrap in empty space takes a fraction of a second.
TINY = ArmSpec(name="tiny8", n_links=8, link_length=0.02)
PLANAR1 = ExploreConfig(mode="planar", directions=1, attempts=1)


def _one_line(msg: str) -> str:
    assert "\n" not in msg, msg
    return msg


def test_no_contact_is_real_and_named():
    """The arm genuinely touches nothing (the rough centre 1 m away): NoContactError with the wraps
    that were run and the fix."""
    with pytest.raises(NoContactError) as info:
        run(load_object("cube"), TINY, PLANAR1, centre=(1.0, 0.0, 0.0), radius=0.06)
    ex = info.value.exploration
    assert ex is not None and ex.n_contacts == 0 and ex.n_wraps == 1 and ex.steps > 0
    msg = _one_line(str(info.value))
    for fix in ("arm", "size", "centre", "radius"):
        assert fix in msg


def test_an_object_far_too_big_for_the_arm_is_refused_before_any_wrap(monkeypatch):
    """A 3 m cube (rough radius 2.7 m) for an arm that reaches 0.16 m: refused up front, naming the
    fix (it used to explore a wrap that touched nothing first)."""
    import explore3d.app.pipeline

    monkeypatch.setattr(explore3d.app.pipeline, "explore", lambda *a, **k: pytest.fail("explored"))
    with pytest.raises(ValueError) as info:
        run(load_object("cube", size=3.0), TINY, PLANAR1)
    msg = _one_line(str(info.value))
    for fix in ("arm", "size", "radius"):
        assert fix in msg


def test_wrong_rough_bound_is_what_the_robot_uses():
    """With the rough centre 1 m away the wrap is placed there: its base is outside the given radius
    and within the arm's reach of the given centre, far from the cube (at the origin)."""
    c = np.array([1.0, 0.0, 0.0])
    with pytest.raises(NoContactError) as info:
        run(load_object("cube"), TINY, PLANAR1, centre=c, radius=0.06)
    base = info.value.exploration.poses[0].T_world_base[:3, 3]
    assert 0.06 < np.linalg.norm(base - c) < 0.06 + TINY.reach
    assert np.linalg.norm(base) > 1.0 - 0.06 - TINY.reach


def test_points_not_around_the_centre_raise_reconstruction_error():
    """One short wrap from one side does not surround the rough centre: a ValueError naming the fix."""
    with pytest.raises(ReconstructionError) as info:
        run(load_object("cube"), TINY, dataclasses.replace(PLANAR1, points="links"))
    assert isinstance(info.value, ValueError)
    assert info.value.exploration.n_contacts > 0
    msg = _one_line(str(info.value))
    assert "outside the convex hull" in msg and "link points" in msg and "directions" in msg


def test_too_few_localised_contacts_raise_reconstruction_error():
    """The same wrap, localised contacts: too few for a shape; the message names them and the fix."""
    with pytest.raises(ReconstructionError) as info:
        run(load_object("cube"), TINY, PLANAR1)
    assert info.value.exploration.n_contacts > 0
    assert info.value.exploration.contacts.used.sum() < 3
    msg = _one_line(str(info.value))
    assert "localised contacts" in msg and "directions" in msg and "attempts" in msg


@pytest.mark.parametrize("kw,word", [({"centre": (0.0, 0.0)}, "3 components"),
                                     ({"centre": (0.0, np.nan, 0.0)}, "finite"),
                                     ({"radius": 0.0}, "radius"), ({"radius": -1.0}, "radius")])
def test_bad_rough_bound(kw, word):
    with pytest.raises(ValueError) as info:
        run(load_object("cube"), TINY, PLANAR1, **kw)
    assert word in _one_line(str(info.value))


def test_run_positional_call_progress_and_result():
    """The documented positional signature; the hull uses exactly the points within the rough radius."""
    calls = []
    arm = ArmSpec(name="small16", n_links=16, link_length=0.02)
    res = run(load_object("cylinder"), arm, ExploreConfig(mode="planar", directions=3), 0.1,
              "exponential", lambda done, total: calls.append((done, total)))
    assert calls == [(1, 3), (2, 3), (3, 3)]
    c, radius = rough_bound(load_object("cylinder").vertices)
    np.testing.assert_array_equal(res.centre, c)
    assert res.radius == radius
    P = res.exploration.points
    inside = np.linalg.norm(P - c[:2], axis=1) <= radius
    assert res.n_points_used == int(inside.sum()) == len(res.hull.points)
    assert 0 < res.n_points_used <= len(P)
    assert res.estimate.equals(res.hull.polygon)
    assert np.linalg.norm(np.asarray(res.estimate.exterior.coords) - c[:2], axis=1).max() <= radius
    assert np.isfinite(res.error.percent) and 0 < res.error.iou <= 1


def test_takes_phase():
    from explore3d.strategy.explore import takes_phase

    assert not takes_phase(lambda done, total: None)
    assert takes_phase(lambda done, total, phase: None)
    assert takes_phase(lambda done, total, phase="wraps": None)
    assert takes_phase(lambda *args: None)


def test_progress_with_a_phase_names_the_planned_wraps_then_each_probe_round():
    """A three-argument progress hears each phase as it starts and after each wrap: the contact
    band, the planned wraps, then each round of probes, every wrap counted against the most the run
    can make (6 planned + 2 rounds x 2 targets x 1 orientation = 10), stated from the start and
    never changed, then reconstructing and scoring (a two-argument one hears only the calls after
    each wrap: test_run_positional_call_progress_and_result)."""
    from explore3d.strategy.explore import ProbeConfig

    probes = ProbeConfig(rounds=2, targets=2, orientations=1, across=False, fingers=0, pokes=0, min_change=0.0)
    config = ExploreConfig(directions=6, offsets=1, angles=1, attempts=1, jobs=1, probes=probes)
    calls = []
    res = run(load_object("cube"), "default", config, progress=lambda d, t, phase: calls.append((d, t, phase)))
    ex = res.exploration
    sizes = [r["wraps"] for r in ex.probe_rounds]
    assert sizes and ex.n_wraps == 6 + sum(sizes)
    most = 10
    expected, done = [(0, None, "contact band")], 0
    for phase, n in [("planned wraps", 6)] + [(f"probe round {k + 1} of at most 2", n) for k, n in enumerate(sizes)]:
        if phase.startswith("probe"):  # the round's targets are planned first (the bar says so)
            expected.append((done, most, "planning " + phase))
        expected += [(done + i, most, phase) for i in range(n + 1)]  # as it starts, then after each wrap
        done += n
    if len(sizes) < 2:  # a round planned that found nothing to run
        expected.append((done, most, f"planning probe round {len(sizes) + 1} of at most 2"))
    expected += [(done, None, "reconstructing"), (done, None, "scoring")]
    assert calls == expected


def test_within_bound():
    P = np.array([[0.0, 0.0], [0.1, 0.0], [0.2, 0.0]])
    np.testing.assert_array_equal(within_bound(P, (0.05, 0.0, 9.0), 0.05), [True, True, False])


@pytest.mark.parametrize("dx,dy", [(0.03, 0.03), (0.02, 0.0), (0.04, 0.0), (0.02, 0.01)])
def test_planar_truth_of_overlapping_and_touching_bodies(dx, dy):
    """Two 40 mm boxes, the second moved by (dx, dy) (as pieces of a convex decomposition): the
    planar truth is their union (trimesh's joint section of such meshes is wrong, see the first assert)."""
    a = trimesh.creation.box([0.04, 0.04, 0.04])
    b = trimesh.creation.box([0.04, 0.04, 0.04])
    b.apply_translation([dx, dy, 0.0])
    mesh = trimesh.util.concatenate([a, b])
    union_area = 2 * 0.04 ** 2 - (0.04 - dx) * (0.04 - dy)
    joint = cross_section(mesh, 0.0)
    assert not (joint.is_valid and joint.area == pytest.approx(union_area, rel=1e-9))  # the case being handled
    truth = planar_truth(mesh, 0.0)
    assert truth.is_valid and truth.geom_type == "Polygon"
    assert truth.area == pytest.approx(union_area, rel=1e-9)


def test_planar_truth_keeps_cavities_and_single_bodies():
    outer = trimesh.creation.box([0.06, 0.06, 0.06])
    inner = trimesh.creation.box([0.02, 0.02, 0.02])
    inner.invert()  # an inward-wound inner shell: a cavity
    hollow = planar_truth(trimesh.util.concatenate([outer, inner]), 0.0)
    assert hollow.area == pytest.approx(0.06 ** 2 - 0.02 ** 2, rel=1e-9)
    cube = load_object("cube")
    assert planar_truth(cube, 0.01).equals(cross_section(cube, 0.01))  # one body: the section as it is
    with pytest.raises(ValueError, match="does not cut"):
        planar_truth(trimesh.util.concatenate([outer, inner]), 1.0)


# --- scripts/explore_*.py (public API only) ---------------------------------------------------------

SCRIPTS = Path(__file__).resolve().parents[1] / "scripts"


def _script(name, *args, cwd=None):
    env = dict(os.environ, PYTHONPATH=str(SCRIPTS.parent))
    return subprocess.run([sys.executable, str(SCRIPTS / name), *args], capture_output=True, text=True, env=env,
                          timeout=120, cwd=cwd)


SCRIPT_NAMES = ("explore_cube.py", "explore_cylinder.py", "explore_concave.py", "explore_mesh.py")


def test_script_help():
    """Each script's --help (in one interpreter, as ``python scripts/NAME --help`` runs it)."""
    code = ("import runpy, sys\n"
            f"sys.path.insert(0, {str(SCRIPTS)!r})\n"
            f"for name in {SCRIPT_NAMES!r}:\n"
            "    sys.argv = [name, '--help']\n"
            "    try:\n"
            f"        runpy.run_path({str(SCRIPTS)!r} + '/' + name, run_name='__main__')\n"
            "    except SystemExit as e:\n"
            "        print('exit', e.code)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       env=dict(os.environ, PYTHONPATH=str(SCRIPTS.parent)))
    assert r.returncode == 0, r.stderr
    chunks = r.stdout.split("exit 0\n")
    assert len(chunks) == len(SCRIPT_NAMES) + 1 and chunks[-1] == "", r.stdout
    for name, text in zip(SCRIPT_NAMES, chunks):
        assert text.startswith(f"usage: {name}") and "--quick" in text and "--out" in text, text


def test_script_bad_input_is_one_line(tmp_path):
    r = _script("explore_mesh.py", str(tmp_path / "missing.stl"), "--quick", "--out", str(tmp_path / "o"))
    assert r.returncode == 1
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("explore_mesh: error: ") and "missing.stl" in lines[0], r.stderr


def test_explore_cube_script_end_to_end(tmp_path):
    """``explore_cube.py --quick --mode planar``: the printed figures are those of summary.json, which
    are the error of the written polygon against the cube's section; the files it lists exist."""
    from shapely.geometry import Polygon

    from explore3d import shape_error

    out = tmp_path / "cube"
    r = _script("explore_cube.py", "--quick", "--mode", "planar", "--out", str(out), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["object"] == "cube" and summary["quick"] and summary["n_wraps"] == 3
    assert f"cube: {summary['percent_error']:.1f} % error, IoU {summary['iou']:.3f}" in r.stdout
    assert sorted(summary["files"]) == sorted(f.name for f in out.iterdir())
    assert {"estimate.obj", "estimate.urdf", "points.ply", "figure.png"} <= set(summary["files"])
    poly = Polygon(json.loads((out / "estimate_polygon.json").read_text()))
    err = shape_error(poly, cross_section(load_object("cube"), summary["centre_m"][2]))
    assert summary["percent_error"] == pytest.approx(err.percent, rel=1e-12)
    assert np.isfinite(err.percent) and err.percent > 0
    # the extrusion covers what the arm sensed (its plane +- half a link height), not the cube's 80 mm
    est = trimesh.load(str(out / "estimate.obj"))
    h = load_arm("default").link_height
    assert est.is_watertight and est.volume == pytest.approx(poly.area * h, rel=1e-5)
    np.testing.assert_allclose(est.bounds[:, 2], summary["centre_m"][2] + np.array([-h, h]) / 2, atol=1e-7)
    # no PyBullet banner on either stream (explore3d.quiet_c_output)
    for banner in PYBULLET_BANNERS:
        assert banner not in r.stdout and banner not in r.stderr, banner
    # stderr is not a terminal: the progress is one line per phase, up to writing, and nothing else
    phases = r.stderr.splitlines()
    assert phases and all(ln.startswith("explore_cube: ") for ln in phases), r.stderr
    assert "explore_cube: reconstructing" in phases and phases[-1] == "explore_cube: writing", r.stderr


def test_explore_script_quiet_shows_no_progress(tmp_path):
    r = _script("explore_cube.py", "--quick", "--mode", "planar", "--out", str(tmp_path / "c"), "--no-pictures", "-q",
                cwd=tmp_path)
    assert r.returncode == 0 and r.stderr == "", r.stderr
    assert r.stdout.startswith("cube: ")


# --- the outlier filter of the reconstruction --------------------------------------------------------

def _sphere_groups(n_groups=12, per=200, radius=0.05, seed=0):
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n_groups * per, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return radius * u, np.repeat(np.arange(n_groups), per)


def test_angular_outliers_flags_points_deep_inside_and_nothing_on_a_clean_sphere():
    from explore3d.reconstruction.hull_input import angular_outliers

    P, g = _sphere_groups()
    assert not angular_outliers(P, np.zeros(3), g).any()
    # one wrap's link that ended 10 mm from the centre (inside a 50 mm sphere)
    bad = np.array([[0.01, 0.0, 0.0], [0.0, 0.012, 0.0]])
    Q = np.vstack([P, bad])
    G = np.append(g, [3, 3])
    out = angular_outliers(Q, np.zeros(3), G)
    assert out[-2:].all() and not out[:-2].any()
    # a rigid motion of everything (points and centre) changes nothing
    R = np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))[0]
    t = np.array([0.3, -0.2, 0.1])
    assert np.array_equal(angular_outliers(Q @ R.T + t, t, G), out)


def test_angular_outliers_keeps_a_star_shaped_concave_outline():
    """A 5-pointed star (inner radius 0.4 x outer) sampled by several groups: concave, star-shaped
    about its centre, nothing dropped."""
    from explore3d.reconstruction.hull_input import angular_outliers

    t = np.linspace(0, 2 * np.pi, 2000, endpoint=False)
    rad = 0.05 * (0.7 + 0.3 * np.cos(5 * t))  # 0.02 .. 0.05 m
    P = np.stack([rad * np.cos(t), rad * np.sin(t)], axis=1)
    g = np.arange(len(t)) % 7
    assert not angular_outliers(P, np.zeros(2), g).any()


def test_angular_outliers_points_without_other_wraps_are_kept():
    from explore3d.reconstruction.hull_input import angular_outliers

    P = np.array([[0.05, 0.0], [0.01, 0.0], [0.0, 0.05]])
    assert not angular_outliers(P, np.zeros(2), np.zeros(3, dtype=int)).any()
