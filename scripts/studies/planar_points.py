"""Planar default runs (3 directions x 4 attempts) of every built-in object, hulled from the paper's
link points and from the localised contacts: area error and point counts (BENCHMARKS.md).

    python scripts/studies/planar_points.py
"""
from explore3d import ExploreConfig, load_object
from explore3d.app.pipeline import run
for obj in ("cube", "box", "cylinder", "sphere", "capsule", "cone", "l_block", "u_channel", "star_prism"):
    row = [obj]
    for pts in ("links", "contacts"):
        try:
            res = run(load_object(obj), config=ExploreConfig(mode="planar", points=pts, jobs=1))
            row.append(f"{res.error.percent:.2f}% ({len(res.exploration.points)})")
        except Exception as e:
            row.append("no polygon: " + str(e)[:60])
    print(" | ".join(row), flush=True)
