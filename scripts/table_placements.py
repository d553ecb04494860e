"""The table scene over several placements of the same object (one run is one sample): each
object turned about the vertical by each of ``--yaws`` degrees before it is put on the table, then
``scene_explore_config("table")`` as ``explore3d run OBJECT --scene table`` runs it.  The table
scene's link points do not use the torque readings, so the sensors' noise seed does not vary its
runs; a placement does (BENCHMARKS.md, "Table scene: the solver").

    python scripts/table_placements.py --objects cube cylinder --yaws 0 10 20 --out /tmp/place.jsonl

Per run: the volume error, IoU, wraps, the object's drift and the false detections (evaluation
only, :class:`explore3d.world.scene.SceneWatch`) and the wall time of the exploration; with
``--detail`` also the wraps the robot flagged as having moved the object, what its registration of
each later epoch found and did (:func:`explore3d.strategy.motion.carry_back`) and the object's true
drift after every wrap, to compare them.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time
from pathlib import Path


def one(name: str, yaw_deg: float, detail: bool = False, register: bool = False, detector: str | None = None,
        settle: str | None = None, held_load: str | None = None) -> dict:
    import trimesh

    from explore3d.app.pipeline import NoContactError, ReconstructionError, exploration_summary, run
    from explore3d.world.objects import load_object
    from explore3d.world.scene import SceneWatch, scene_explore_config, settle_scene

    cfg = scene_explore_config("table", detector=detector)
    if settle is not None:
        cfg = dataclasses.replace(cfg, control=dataclasses.replace(cfg.control, press_while_settling=settle == "press"))
    if held_load is not None:
        cfg = dataclasses.replace(cfg, control=dataclasses.replace(cfg.control, held_load_action=held_load))
    if register:
        cfg = dataclasses.replace(cfg, scene=dataclasses.replace(cfg.scene, register_moved=True))
    mesh = load_object(name).copy()
    mesh.apply_transform(trimesh.transformations.rotation_matrix(math.radians(yaw_deg), [0, 0, 1]))
    setup = settle_scene(mesh, cfg.scene, sim=cfg.sim)
    watch = SceneWatch(setup)
    t0 = time.perf_counter()
    try:
        res = run(mesh, "default", cfg, setup=setup, after_wrap=watch.after_wrap)
    except (NoContactError, ReconstructionError) as exc:  # e.g. the object rolled away: no estimate
        wall = time.perf_counter() - t0
        s = watch.summary(exc.exploration) if exc.exploration is not None else {}
        return {"object": name, "yaw_deg": yaw_deg, "error": str(exc).split(";")[0], "wall_s": round(wall, 1),
                "max_drift_mm": round(1e3 * s.get("max_drift_m", float("nan")), 2)}
    wall = time.perf_counter() - t0
    s = watch.summary(res.exploration)
    force = s["touch_force_n"]
    om = exploration_summary(res.exploration).get("object_motion", {})  # the robot's own verdict on its motion
    return {"object": name, "yaw_deg": yaw_deg, "detector": cfg.control.detector,
            "settle": "press" if cfg.control.press_while_settling else "hold",
            "held_load": cfg.control.held_load_action, "register_moved": register, "percent_error": round(res.error.percent, 2),
            "iou": round(res.error.iou, 3), "wraps": res.exploration.n_wraps, "wall_s": round(wall, 1),
            "band_s": round(res.exploration.band_s, 1),
            "drift_mm": round(1e3 * s["drift_m"], 2), "drift_deg": round(s["drift_deg"], 2),
            "max_drift_mm": round(1e3 * s["max_drift_m"], 2), "false_detections": s["false_detections"],
            "detections": s["detections_watched"], "flagged": len(s.get("wraps_flagged_moved", [])),
            "wraps_moving_object": len(s["wraps_moving_object"]),  # the truth: > 1 mm or 1 deg in the wrap
            "motion_verdict": om.get("verdict"), "consistent_fraction": round(om.get("consistent_fraction", math.nan), 3),
            "touches": force["touches"], "peak_force_n": {k: round(v, 3) for k, v in (force["peak"] or {}).items()},
            "held_force_n": {k: round(v, 3) for k, v in (force["held"] or {}).items()}} | (
        {"wraps_flagged_moved": s.get("wraps_flagged_moved", []), "registrations": s["registrations"],
         "drift_after_wrap_mm": [round(1e3 * d, 2) for d in s["drift_after_wrap_m"]],
         "drift_after_wrap_deg": [round(d, 2) for d in s["drift_after_wrap_deg"]]} if detail else {})


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", nargs="+", default=["cube", "cylinder"])
    ap.add_argument("--yaws", type=float, nargs="+", default=[0.0, 10.0, 20.0], help="degrees")
    ap.add_argument("--out", required=True, help="JSON lines file (appended)")
    ap.add_argument("--detail", action="store_true",
                    help="also the flagged wraps, the robot's registrations (carry_back) and the true drift after each wrap")
    ap.add_argument("--register", action="store_true",
                    help="SceneConfig.register_moved=True: carry the points after a flagged wrap back (off by default)")
    ap.add_argument("--detector", choices=["stall", "torque"], default=None,
                    help="the contact detector (ControlConfig.detector; default: the table scene's)")
    ap.add_argument("--held-load", choices=["stop", "contact"], default=None,
                    help="a torque stop seen only behind held links: stop without a contact, or a contact "
                         "(ControlConfig.held_load_action; default: the table scene's)")
    ap.add_argument("--settle", choices=["press", "hold"], default=None,
                    help="after a detection, settle pressing on at the budget or holding the stopped pose "
                         "(ControlConfig.press_while_settling; default: the table scene's)")
    args = ap.parse_args(argv)
    for name in args.objects:
        for yaw in args.yaws:
            row = one(name, yaw, args.detail, args.register, args.detector, args.settle, args.held_load)
            with Path(args.out).open("a") as fh:
                fh.write(json.dumps(row) + "\n")
            print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
