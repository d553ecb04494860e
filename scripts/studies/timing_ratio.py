"""Exploration wall time and physics steps of the default 3D runs on the cube and the cylinder (2 jobs),
after a small warm-up run (imports, band cache).  Run it on two commits one after the other and
compare the ratios (BENCHMARKS.md, first section):

    python scripts/studies/timing_ratio.py            # prints JSON {object: {wall_s, steps, total_s}}
"""
import sys, time, json
from explore3d import ExploreConfig, load_object
from explore3d.world.explore import explore
out = {}
for obj in ("cube", "cylinder"):
    mesh = load_object(obj)
    explore(mesh, config=ExploreConfig(jobs=2, directions=2, angles=1))  # warm the band cache / imports
    t = time.perf_counter()
    ex = explore(mesh, config=ExploreConfig(jobs=2))
    out[obj] = {"wall_s": ex.wall_s, "steps": ex.steps, "total_s": time.perf_counter() - t}
print(json.dumps(out))
