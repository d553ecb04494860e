"""The table scene's ablation: each idealisation turned on in turn (BENCHMARKS.md, "Table scene").

    python scripts/studies/scene_ablation.py --objects cube cylinder l_block --out /tmp/ablation.jsonl

Rows (each from the table scene as ``explore3d run --scene table`` runs it, one change at a time):
``table`` (resting, friction 0.5, 5% mass error, persistent), ``fixed`` (the object fixed in place),
``friction 0``, ``exact model``, ``reset world`` (every wrap from the settled scene), ``floating``
(no table: the ideal scene's wraps all round, fixed object, same controller and solver), and
``ideal`` (the README's main command: the ideal scene with its own controller, solver and
localised contacts).  Per run: volume error, IoU, the object's drift (evaluation only), the
false detections (a detection with no link touching the object in the 10 steps up to it,
PyBullet's contact points: evaluation only), flagged and repeated wraps, wraps and time.
One JSON line per run is appended to ``--out`` (runs already there are skipped), then a markdown
table is printed.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time
from pathlib import Path

ROWS = ("table", "fixed", "friction 0", "exact model", "reset world", "floating", "ideal")


def config_for(row: str):
    from explore3d.strategy.explore import ExploreConfig
    from explore3d.core.settings import SceneConfig
    from explore3d.world.scene import scene_explore_config

    cfg = scene_explore_config("table")
    sc = cfg.scene
    if row == "table":
        return cfg
    if row == "fixed":
        return dataclasses.replace(cfg, scene=dataclasses.replace(sc, resting=False))
    if row == "friction 0":
        return dataclasses.replace(cfg, scene=dataclasses.replace(sc, friction=0.0))
    if row == "exact model":
        return dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, mass_error=0.0))
    if row == "reset world":
        return dataclasses.replace(cfg, scene=dataclasses.replace(sc, persistent=False))
    if row == "floating":
        return dataclasses.replace(cfg, scene=SceneConfig())
    if row == "ideal":
        return ExploreConfig()
    raise ValueError(f"unknown row {row!r}; valid: {', '.join(ROWS)}")


def one(name: str, row: str) -> dict:
    from explore3d.world.objects import load_object
    from explore3d.app.pipeline import run
    from explore3d.world.scene import SceneWatch, settle_scene

    cfg = config_for(row)
    mesh = load_object(name)
    setup = settle_scene(mesh, cfg.scene, sim=cfg.sim)
    watch = SceneWatch(setup)
    t0 = time.perf_counter()
    res = run(mesh, "default", cfg, setup=setup, after_wrap=watch.after_wrap)
    wall = time.perf_counter() - t0
    s = watch.summary(res.exploration)
    return {"object": name, "row": row, "percent_error": res.error.percent, "iou": res.error.iou,
            "drift_mm": 1000 * s["drift_m"], "drift_deg": s["drift_deg"], "max_drift_mm": 1000 * s["max_drift_m"],
            "false_detections": s["false_detections"], "detections": s["detections_watched"],
            "false_fraction": s["false_detection_fraction"], "flagged": len(s.get("wraps_flagged_moved", [])),
            "redone": len(s.get("wraps_redone", [])), "wraps_moving_object": len(s["wraps_moving_object"]),
            "wraps": res.exploration.n_wraps, "explore_s": res.exploration.wall_s, "total_s": wall,
            "band_s": res.exploration.band_s}


def table(rows: list[dict]) -> str:
    out = ["| object | scene | volume error % | IoU | drift mm / deg | false detections | flagged / redone | wraps | time s |",
           "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['object']} | {r['row']} | {r['percent_error']:.2f} | {r['iou']:.3f} | "
                   f"{r['drift_mm']:.2f} / {r['drift_deg']:.2f} | {r['false_detections']} / {r['detections']} "
                   f"({100 * r['false_fraction']:.1f}%) | {r['flagged']} / {r['redone']} | {r['wraps']} | "
                   f"{r['explore_s']:.0f} |")
    return "\n".join(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", nargs="+", default=["cube", "cylinder", "l_block"])
    ap.add_argument("--rows", nargs="+", default=list(ROWS), choices=ROWS)
    ap.add_argument("--out", required=True, help="JSON lines file (appended; finished runs are skipped)")
    args = ap.parse_args()
    out = Path(args.out)
    done = [json.loads(l) for l in out.read_text().splitlines() if l.strip()] if out.exists() else []
    have = {(d["object"], d["row"]) for d in done}
    for name in args.objects:
        for row in args.rows:
            if (name, row) in have:
                continue
            try:
                d = one(name, row)
            except Exception as exc:  # a failed run is a result too
                d = {"object": name, "row": row, "error": f"{type(exc).__name__}: {exc}"[:300],
                     "percent_error": math.nan, "iou": math.nan, "drift_mm": math.nan, "drift_deg": math.nan,
                     "max_drift_mm": math.nan, "false_detections": -1, "detections": -1, "false_fraction": math.nan,
                     "flagged": -1, "redone": -1, "wraps_moving_object": -1, "wraps": -1, "explore_s": math.nan,
                     "total_s": math.nan, "band_s": math.nan}
            with out.open("a") as fh:
                fh.write(json.dumps(d) + "\n")
            done.append(d)
            print(json.dumps(d), flush=True)
    print(table([d for d in done if d["object"] in args.objects]))


if __name__ == "__main__":
    main()
