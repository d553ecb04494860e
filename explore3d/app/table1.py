"""The paper's Table I reproduced in simulation, side by side with the paper's figures.

Rows (paper section IV): the 4 x 110 mm arm on the 80 mm cube and on the 63 mm-radius cylinder
(100-gon), four attempts, one direction and two (mirrored); and the simulated many-small-links cube
(320 random links of 8 mm).  We add the paper's recommendation (three directions 90 degrees apart)
and our default many-small-links arm for comparison.  Area errors in m^2, a = 0.2 as in the paper.
"""
from __future__ import annotations

import dataclasses

from explore3d.app.pipeline import reconstruct_exploration, run
from explore3d.core.defaults import DEFAULT_A, PAPER_A
from explore3d.geometry.metrics import shape_error
from explore3d.strategy.explore import ExploreConfig, contact_points
from explore3d.world.calibration import calibrate_thickness
from explore3d.world.objects import load_object, square
from explore3d.world.simulated import simulated_case

#: (case, paper area error m^2, paper percent) from Table I of the paper.
PAPER_TABLE_I = {
    "Cube one direction": (0.0026, 40.6),
    "Cube two directions": (0.0014, 21.9),
    "Simulated Cube": (0.00021, 3.3),
    "Cylinder one direction": (0.0013, 41.9),
    "Cylinder two directions": (0.00088, 28.4),
}


def _planar_row(case, obj, arm, directions, mirrored, attempts=4, a=PAPER_A):

    res = run(load_object(obj), arm, ExploreConfig(mode="planar", directions=directions, mirrored=mirrored,
                                                 attempts=attempts, points="links"), a=a)  # the paper's rule
    paper = PAPER_TABLE_I.get(case, (None, None))
    return {"case": case, "arm": str(arm), "paper_area_error_m2": paper[0], "paper_percent": paper[1],
            "area_error_m2": res.error.sym_diff, "percent": res.error.percent}


def table1_rows(a: float = PAPER_A, seed: int = 0) -> list[dict]:
    """The reproduced rows (list of dicts with case, arm, paper_area_error_m2, paper_percent,
    area_error_m2, percent)."""

    rows = [
        _planar_row("Cube one direction", "cube", "paper", 1, False, a=a),
        _planar_row("Cube two directions", "cube", "paper", 2, True, a=a),
        _planar_row("Cube three directions (90 deg)", "cube", "paper", 3, False, a=a),
    ]
    sim = simulated_case(square(), n_links=320, link_length=0.008, a=a, seed=seed)
    paper = PAPER_TABLE_I["Simulated Cube"]
    rows.append({"case": "Simulated Cube", "arm": "320 random 8 mm links", "paper_area_error_m2": paper[0],
                 "paper_percent": paper[1], "area_error_m2": sim.error.sym_diff, "percent": sim.error.percent})
    rows += [
        _planar_row("Cylinder one direction", "cylinder", "paper", 1, False, a=a),
        _planar_row("Cylinder two directions", "cylinder", "paper", 2, True, a=a),
        _planar_row("Cylinder three directions (90 deg)", "cylinder", "paper", 3, False, a=a),
        _planar_row("Cube two directions, default arm", "cube", "default", 2, True, a=a),
        _planar_row("Cube three directions, default arm", "cube", "default", 3, False, a=a),
    ]
    return rows


#: The 3D objects of the issue's table: (case, built-in object).
TABLE_3D_OBJECTS = (("3D cube 80 mm", "cube"), ("3D cylinder r 63 mm", "cylinder"), ("3D sphere r 50 mm", "sphere"))


def table3d_rows(a: float = DEFAULT_A, arm="default", config=None, calibrate: bool = True, jobs: int | None = None,
                 progress=None) -> list[dict]:
    """The default arm's 3D volume errors on the cube, the cylinder and the sphere.

    Each object is explored with ``config`` (default: ``ExploreConfig(jobs=jobs, points="links")``,
    the 3D defaults with the paper's link points, which the calibrated thickness corrects) and
    reconstructed from joint angles alone; with ``calibrate`` the contact thickness
    is first calibrated once on the known 60 mm ball (:func:`explore3d.world.calibration.calibrate_thickness`,
    never one of the objects under test) and every object is also reconstructed with it.  Returns
    dicts with case, object, arm, n_wraps, a, percent and volume_error_m3 (uncalibrated),
    face_offset_m, percent_calibrated, volume_error_calibrated_m3 (None without calibration),
    wall_s (exploration wall time, uncalibrated run).
    """

    config = ExploreConfig(jobs=jobs, points="links") if config is None else config
    offset = None
    if calibrate:
        offset = calibrate_thickness(arm, config).face_offset_m
    rows = []
    for case, obj in TABLE_3D_OBJECTS:
        mesh = load_object(obj)
        res = run(mesh, arm, config, a=a, progress=progress)
        ex = res.exploration
        row = {"case": case, "object": obj, "arm": str(arm), "n_wraps": ex.n_wraps, "a": a,
               "percent": res.error.percent, "volume_error_m3": res.error.sym_diff, "face_offset_m": offset,
               "percent_calibrated": None, "volume_error_calibrated_m3": None, "wall_s": ex.wall_s}
        if offset is not None:
            # The same joint angles, the faces pushed in by the calibrated thickness.
            cal = dataclasses.replace(ex.config, face_offset=offset)
            ex_cal = dataclasses.replace(ex, config=cal, points=contact_points(ex.spec, ex.attempts, cal)[0])
            hull = reconstruct_exploration(ex_cal, res.centre, res.radius, a=a)
            err = shape_error(hull.shape(), mesh)
            row["percent_calibrated"] = err.percent
            row["volume_error_calibrated_m3"] = err.sym_diff
        rows.append(row)
    return rows


def format_table3d(rows) -> str:
    """A plain-text table of :func:`table3d_rows`."""
    head = (f"{'case':22s} {'arm':10s} {'wraps':>5s} {'volume err %':>12s} {'calibrated %':>12s} "
            f"{'offset mm':>9s} {'wall s':>7s}")
    lines = [head, "-" * len(head)]
    for r in rows:
        pc = "" if r["percent_calibrated"] is None else f"{r['percent_calibrated']:.1f}"
        off = "" if r["face_offset_m"] is None else f"{r['face_offset_m'] * 1000:.2f}"
        lines.append(f"{r['case']:22s} {r['arm']:10s} {r['n_wraps']:5d} {r['percent']:12.1f} {pc:>12s} "
                     f"{off:>9s} {r['wall_s']:7.1f}")
    return "\n".join(lines)


def format_table(rows) -> str:
    """A plain-text table of :func:`table1_rows`."""
    head = f"{'case':38s} {'arm':22s} {'paper m^2':>10s} {'paper %':>8s} {'ours m^2':>10s} {'ours %':>8s}"
    lines = [head, "-" * len(head)]
    for r in rows:
        pa = "" if r["paper_area_error_m2"] is None else f"{r['paper_area_error_m2']:.5f}"
        pp = "" if r["paper_percent"] is None else f"{r['paper_percent']:.1f}"
        lines.append(f"{r['case']:38s} {r['arm']:22s} {pa:>10s} {pp:>8s} {r['area_error_m2']:10.5f} {r['percent']:8.1f}")
    return "\n".join(lines)


if __name__ == "__main__":
    import sys

    print(format_table(table1_rows()))
    if "--3d" in sys.argv[1:]:
        print()
        print(format_table3d(table3d_rows(jobs=None)))
