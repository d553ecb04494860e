"""The paper's Table I reproduced in simulation, side by side with the paper's figures.

Rows (paper section IV): the 4 x 110 mm arm on the 80 mm cube and on the 63 mm-radius cylinder
(100-gon), four attempts, one direction and two (mirrored); and the simulated many-small-links cube
(320 random links of 8 mm).  We add the paper's recommendation (three directions 90 degrees apart)
and our default many-small-links arm for comparison.  Area errors in m^2, a = 0.2 as in the paper.
"""
from __future__ import annotations

#: (case, paper area error m^2, paper percent) from Table I of the paper.
PAPER_TABLE_I = {
    "Cube one direction": (0.0026, 40.6),
    "Cube two directions": (0.0014, 21.9),
    "Simulated Cube": (0.00021, 3.3),
    "Cylinder one direction": (0.0013, 41.9),
    "Cylinder two directions": (0.00088, 28.4),
}


def _planar_row(case, obj, arm, directions, mirrored, attempts=4, a=0.2):
    from .explore import ExploreConfig
    from .objects import load_object
    from .pipeline import run

    res = run(load_object(obj), arm, ExploreConfig(mode="planar", directions=directions, mirrored=mirrored,
                                                 attempts=attempts), a=a)
    paper = PAPER_TABLE_I.get(case, (None, None))
    return {"case": case, "arm": str(arm), "paper_area_error_m2": paper[0], "paper_percent": paper[1],
            "area_error_m2": res.error.sym_diff, "percent": res.error.percent}


def table1_rows(a: float = 0.2, seed: int = 0) -> list[dict]:
    """The reproduced rows (list of dicts with case, arm, paper_area_error_m2, paper_percent,
    area_error_m2, percent)."""
    from .objects import square
    from .simulated import simulated_case

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
    print(format_table(table1_rows()))
