"""Where a run's time goes (issue 42, item 1; BENCHMARKS.md, "Where a default run's time goes").

    python scripts/studies/profile_run.py [--object cube] [--noise-seed 0] [--out prof.json]

Runs ``explore3d run OBJECT`` in this process with one job (so one profile holds every wrap),
under :mod:`cProfile`, and sums the functions' own time (``tottime``) by what they do: the
physics step, the simulator's other calls (joint readings, motor commands, contact queries of the
evaluation), the controller and detector (``explore3d.strategy.encircle``, ``explore3d.feeling.detect``),
the robot interface and sensing, localisation, the hull, carving and free space, probe planning,
scoring and writing, numpy and other libraries, and the rest.  Prints a table (seconds, share,
microseconds per simulation step) and writes it as JSON.  The profiler itself slows Python calls
(several times for short ones), so the shares of Python-heavy parts are upper bounds; the
wall time without the profiler is measured first, the same run.
"""
from __future__ import annotations

import argparse
import cProfile
import json
import pstats
import tempfile
import time
from pathlib import Path

#: (category, test on "file:function") in order: the first that matches takes the function's time
#: (the simulator's functions are called through ``functools.partial`` bound to the client, so the
#: profiler books their C time to the calling method: ``ArmSimulation._physics_step`` is the physics
#: step, the other ``world/sim.py`` methods hold the joint readings and motor commands)
CATEGORIES = [
    ("physics step (ArmSimulation._physics_step: pybullet.stepSimulation)", lambda f, n: f.endswith("world/sim.py") and n == "_physics_step"),
    ("simulator calls (joint readings, motor commands: world/sim.py's other methods)", lambda f, n: f.endswith("world/sim.py") or "pybullet" in n),
    ("controller (strategy/encircle, poke, motion)", lambda f, n: any(k in f for k in ("strategy/encircle", "strategy/poke", "strategy/motion"))),
    ("detector (feeling/detect)", lambda f, n: "feeling/detect" in f),
    ("robot interface and sensing (robot/, world/simulated)", lambda f, n: any(k in f for k in ("robot/", "world/simulated"))),
    ("localisation (feeling/localise, contacts)", lambda f, n: any(k in f for k in ("feeling/localise", "feeling/contacts"))),
    ("arm model (arm/kinematics, selfcontact, workspace)", lambda f, n: "explore3d/arm/" in f),
    ("hull (geometry/hull, reconstruction/hull_input)", lambda f, n: any(k in f for k in ("geometry/hull", "hull_input"))),
    ("carving and free space (reconstruction/carve, freespace)", lambda f, n: any(k in f for k in ("reconstruction/carve", "freespace"))),
    ("probe planning (strategy/active, explore)", lambda f, n: any(k in f for k in ("strategy/active", "strategy/explore"))),
    ("scoring and writing (geometry/metrics, app/)", lambda f, n: any(k in f for k in ("geometry/metrics", "explore3d/app/"))),
    ("other explore3d", lambda f, n: "explore3d/" in f),
    ("numpy", lambda f, n: "numpy" in f or "numpy" in n),
    ("scipy, trimesh, open3d, manifold, skimage", lambda f, n: any(k in f or k in n for k in ("scipy", "trimesh", "open3d", "manifold", "skimage"))),
    ("matplotlib (pictures)", lambda f, n: "matplotlib" in f or "PIL" in f),
    ("python built-ins and the rest", lambda f, n: True),
]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--object", default="cube")
    ap.add_argument("--noise-seed", type=int, default=0)
    ap.add_argument("--out", default=None, help="JSON file for the table (optional)")
    ap.add_argument("--stats", default=None, help="also the raw profile (pstats file), or with --from-stats read it")
    ap.add_argument("--from-stats", action="store_true", help="sum an earlier --stats profile (with its --out JSON's "
                                                              "step count) instead of running")
    args = ap.parse_args(argv)
    if args.from_stats:
        meta = json.loads(Path(args.out).read_text())
        return table(pstats.Stats(args.stats).stats, meta["steps"], meta, args.out)
    from explore3d.app.cli import main as cli

    cmd = ["run", args.object, "--noise-seed", str(args.noise_seed), "--jobs", "1", "-q"]
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        assert cli([*cmd, "--out", f"{tmp}/plain"]) == 0
        plain_s = time.perf_counter() - t0
        report = json.loads(Path(f"{tmp}/plain/report.json").read_text())
        prof = cProfile.Profile()
        t0 = time.perf_counter()
        prof.enable()
        assert cli([*cmd, "--out", f"{tmp}/prof"]) == 0
        prof.disable()
        prof_s = time.perf_counter() - t0
    steps = int(report["steps"])
    if args.stats:
        prof.dump_stats(args.stats)
    meta = {"object": args.object, "noise_seed": args.noise_seed, "steps": steps, "wraps": report["n_wraps"],
            "plain_s": plain_s, "profiled_s": prof_s, "timings": report["timings"]}
    return table(pstats.Stats(prof).stats, steps, meta, args.out)


def table(stats: dict, steps: int, meta: dict, out) -> int:
    sums = {c: 0.0 for c, _ in CATEGORIES}
    for (file, _line, name), (_, _, tottime, _, _) in stats.items():
        f = file.replace("\\", "/")
        for c, test in CATEGORIES:
            if test(f, name):
                sums[c] += tottime
                break
    total = sum(sums.values())
    rows = [{"category": c, "s": round(v, 2), "share": round(v / total, 3), "us_per_step": round(1e6 * v / steps, 1)}
            for c, v in sums.items()]
    print(f"{meta['object']}, noise seed {meta['noise_seed']}, one job: {meta['wraps']} wraps, {steps} steps; "
          f"{meta['plain_s']:.1f} s without the profiler (exploration {meta['timings']['explore_s']:.1f} s), "
          f"{meta['profiled_s']:.1f} s under it; profiled total {total:.1f} s")
    print(f"| {'what':80s} | s | share | us per step |")
    for r in rows:
        print(f"| {r['category']:80s} | {r['s']:.2f} | {100 * r['share']:.1f}% | {r['us_per_step']:.1f} |")
    if out:
        Path(out).write_text(json.dumps({**meta, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
