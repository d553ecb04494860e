"""The floating (ideal) scene's touch forces and error for a contact detector over noise seeds
(issue 40; BENCHMARKS.md, "Touch without pushing").

    python scripts/studies/floating_touch.py --objects cube --detectors torque stall --seeds 0 1 2 --out /tmp/float.jsonl

Each row is one default 3D run (``scene_explore_config("ideal", detector=...)``, the sensors'
noise seed set) in one persistent world, so the touches can be watched
(:class:`explore3d.world.scene.SceneWatch`, evaluation only: PyBullet's contact points): the
volume error, wraps, wall time, false detections and the median, 95th percentile and maximum of
every touch's peak and held normal force, N.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import time


def one(name: str, detector: str, seed: int) -> dict:
    from explore3d import load_object
    from explore3d.app.pipeline import run
    from explore3d.world.scene import SceneWatch, scene_explore_config, settle_scene

    cfg = scene_explore_config("ideal", detector=detector)
    cfg = dataclasses.replace(cfg, sensors=dataclasses.replace(cfg.sensors, seed=seed))
    mesh = load_object(name)
    setup = settle_scene(mesh, cfg.scene, sim=cfg.sim)
    watch = SceneWatch(setup)
    t0 = time.perf_counter()
    res = run(mesh, "default", cfg, setup=setup, after_wrap=watch.after_wrap)
    s = watch.summary(res.exploration)
    f = s["touch_force_n"]
    return {"object": name, "scene": "floating", "detector": detector, "noise_seed": seed,
            "percent_error": round(res.error.percent, 2), "wraps": res.exploration.n_wraps,
            "wall_s": round(time.perf_counter() - t0, 1), "false": s["false_detections"],
            "detections": s["detections_watched"], "touches": f["touches"], "peak": f["peak"], "held": f["held"]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", nargs="+", default=["cube"])
    ap.add_argument("--detectors", nargs="+", choices=["stall", "torque"], default=["torque", "stall"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="sensor noise seeds")
    ap.add_argument("--out", required=True, help="JSON lines file (appended)")
    args = ap.parse_args(argv)
    for name in args.objects:
        for seed in args.seeds:
            for det in args.detectors:
                row = one(name, det, seed)
                print(json.dumps(row), flush=True)
                with open(args.out, "a") as f:
                    f.write(json.dumps(row) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
