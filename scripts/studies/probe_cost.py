"""Cost and gain of the free space and the probes in one run: the default 3D exploration of each object
with free space and probes (the default), with free space only (probes=None) and with neither
(the straight sweeps' hull, as before issue 11), one after the other in this process (2 jobs):

    python scripts/studies/probe_cost.py [OBJECT ...]        # default: cube; prints JSON per object and setting

Ratios of the wall times within one run are what to compare (the machine is shared).
"""
import json
import logging
import sys
import time

from explore3d import ExploreConfig, load_object, run

logging.disable(logging.WARNING)
SETTINGS = {"free space + probes": {}, "free space": {"probes": None}, "neither": {"probes": None, "free_space": False}}
out = {}
for obj in sys.argv[1:] or ["cube"]:
    mesh = load_object(obj)
    run(mesh, "default", ExploreConfig(jobs=2, directions=2, angles=1, probes=None))  # warm imports and the band cache
    for label, kw in SETTINGS.items():
        t = time.perf_counter()
        res = run(mesh, "default", ExploreConfig(jobs=2, **kw))
        ex = res.exploration
        out.setdefault(obj, {})[label] = {"percent_error": round(res.error.percent, 2), "wraps": ex.n_wraps,
                                          "explore_s": round(ex.wall_s, 1), "run_s": round(time.perf_counter() - t, 1)}
    print(json.dumps({obj: out[obj]}), flush=True)
