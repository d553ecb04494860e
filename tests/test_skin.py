"""The ideal skin and the compare command (evaluation only)."""
import json

import numpy as np
import pytest

from explore3d import ArmSpec, ExploreConfig, load_object, run
from explore3d.compare import compare, format_compare
from explore3d.sdf import SignedDistance
from explore3d.skin import ideal_skin, surface_coverage

SMALL = ArmSpec(name="small16", n_links=16, link_length=0.02)


@pytest.fixture(scope="module")
def planar_cube():
    cube = load_object("cube")
    res = run(cube, SMALL, ExploreConfig(mode="planar", directions=3, attempts=1))
    return cube, res, ideal_skin(res.exploration, cube)


def test_skin_points_are_on_the_links_at_the_surface(planar_cube):
    """Every skin point is a PyBullet contact point on a link: within the contact margin (plus the
    solver's small penetration) of the true surface, on links of the explored arm."""
    cube, res, skin = planar_cube
    assert len(skin) > 0 and skin.loaded.sum() > 0
    sd = SignedDistance(cube)(skin.points)
    margin = res.exploration.config.sim.collision_margin
    assert np.all(np.abs(sd) <= margin + 1e-3), np.abs(sd).max()
    assert skin.link.min() >= 0 and skin.link.max() < SMALL.n_links
    assert set(skin.wrap.tolist()) <= set(range(res.exploration.n_wraps))
    # readings at detections and at the final holds
    assert skin.final.any() and (~skin.final).any()


def test_skin_is_deterministic(planar_cube):
    cube, res, skin = planar_cube
    again = ideal_skin(res.exploration, cube)
    assert np.array_equal(again.points, skin.points) and np.array_equal(again.normal_force_n, skin.normal_force_n)


def test_coverage_of_known_point_sets():
    """Touches on one face of the 80 mm cube cover one sixth of its surface at radius 0; all of it
    with the surface samples themselves."""
    import trimesh

    cube = load_object("cube")
    S = trimesh.sample.sample_surface(cube, 20000, seed=0)[0]
    assert surface_coverage(cube, S, radii_m=(1e-9,)) == (1.0,)
    top = S[np.isclose(S[:, 2], cube.bounds[1, 2])]
    (frac,) = surface_coverage(cube, top, radii_m=(1e-9,))
    assert frac == pytest.approx(1 / 6, abs=0.01)
    assert surface_coverage(cube, np.zeros((0, 3))) == (0.0, 0.0)


def test_the_skin_beats_the_link_points_on_the_same_sweeps():
    """Where the arm really touched gives a better shape than the whole contact-flagged links
    (measured on the small arm's planar cube: 8.4% against 1.5% area error)."""
    rep = compare(load_object("cube"), SMALL, ExploreConfig(mode="planar", directions=3, attempts=1))
    links, skin, loaded = rep["columns"]
    assert links["name"].startswith("link points") and skin["name"].startswith("ideal skin")
    assert skin["percent_error"] < 0.5 * links["percent_error"]
    assert loaded["n_points"] == rep["skin_loaded"] <= skin["n_points"] == rep["skin_contacts"]
    table = format_compare(rep)
    assert table.count("\n") == 7 and "coverage 3 mm" in table


def test_compare_command_prints_columns_and_json(capsys):
    from explore3d.cli import main

    args = ["compare", "cube", "--arm", "paper", "--mode", "planar", "--directions", "2", "--attempts", "1"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "link points (paper)" in out and "ideal skin, all contacts" in out
    assert main(args + ["--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["object"] == "cube" and len(rep["columns"]) == 3
