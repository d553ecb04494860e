"""Contact at a known force on the table (issue 23, item 1): how precisely do the gentle sweeps'
contacts localise on a resting object, with and without a press at a chosen force and averaged
readings, and does the press move the object?  (BENCHMARKS.md, "Table scene: contact at a known force")

    python scripts/studies/table_press_study.py --object cube --variants gentle press avg press+avg --out /tmp/press.jsonl

Each variant runs the table scene's first wraps (``--heights`` horizontal heights x ``--angles``
approach directions, ``--normals`` tilted planes; the table scene's controller otherwise) on the
object resting on the table, localising every detection.  Per variant: the localised contacts'
distance from the true surface (the nearest point of the located link-face segment; evaluation
only), their stated uncertainty, how many the hull would take (:func:`contacts_for_hull`), their
force, the object's drift (:class:`explore3d.world.scene.SceneWatch`) and the wall time.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

VARIANTS = ("gentle", "press", "avg", "press+avg", "press2+avg")


def control_for(variant: str, budget: float):
    from explore3d.strategy.encircle import ControlConfig

    c = ControlConfig.gentle()
    if variant == "gentle":
        return c
    if variant == "press":
        return dataclasses.replace(c, press_force_n=budget)
    if variant == "avg":
        return dataclasses.replace(c, average_steps=96)
    if variant == "press+avg":
        return dataclasses.replace(c, press_force_n=budget, average_steps=96)
    if variant == "press2+avg":
        return dataclasses.replace(c, press_force_n=budget / 2, average_steps=96)
    raise ValueError(f"unknown variant {variant!r}; valid: {', '.join(VARIANTS)}")


def one(name: str, variant: str, heights: int, angles: int, normals: int, budget: float,
        friction: float | None = None, mass_error: float | None = None, dump: str | None = None) -> dict:
    from explore3d.feeling.contacts import contacts_for_hull
    from explore3d.geometry.sdf import SignedDistance
    from explore3d.strategy.explore import rough_bound
    from explore3d.world.explore import explore
    from explore3d.world.objects import load_object
    from explore3d.world.scene import SceneWatch, scene_explore_config, settle_scene

    cfg = scene_explore_config("table", control=control_for(variant, budget), points="contacts",
                               table_heights=heights, table_angles=angles, directions=normals)
    if friction is not None:
        cfg = dataclasses.replace(cfg, scene=dataclasses.replace(cfg.scene, friction=friction))
    if mass_error is not None:
        cfg = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, mass_error=mass_error))
    mesh = load_object(name)
    setup = settle_scene(mesh, cfg.scene, sim=cfg.sim)
    watch = SceneWatch(setup)
    t0 = time.perf_counter()
    ex = explore(mesh, "default", cfg, setup=setup, after_wrap=watch.after_wrap)
    wall = time.perf_counter() - t0
    c, r = rough_bound(setup.truth.vertices)
    cs = contacts_for_hull(ex.contacts, cfg, c, r)
    sdf = SignedDistance(setup.truth)
    on = ~cs.self_contact
    seg = cs.segments[on]  # (m, 2, 3): the located face across the link's height
    t = np.linspace(0.0, 1.0, 11)[None, :, None]
    pts = seg[:, :1] + t * (seg[:, 1:] - seg[:, :1])
    gap = np.abs(sdf(pts.reshape(-1, 3)).reshape(len(seg), -1)).min(axis=1) if len(seg) else np.zeros(0)
    used = cs.used[on]
    horiz = np.array([abs(ex.poses[w].normal[2]) > 0.99 for w in cs.wrap[on]], dtype=bool)
    s = watch.summary(ex)
    if dump:
        np.savez(dump, gap=gap, force=cs.force_n[on], u=cs.uncertainty_m[on], link=cs.link[on], joint=cs.joint[on],
                 wrap=cs.wrap[on], still=cs.still[on], resid=cs.residual_nm[on], sigma=cs.sigma_nm[on],
                 kind=cs.kind[on], attempt=cs.attempt[on])

    def q(x, p):
        return float(np.percentile(x, p)) if len(x) else float("nan")

    return {"object": name, "variant": variant, "budget_n": budget, "friction": cfg.scene.friction,
            "mass_error": cfg.sim.mass_error, "wraps": ex.n_wraps, "contacts": int(on.sum()),
            "gap_median_mm": 1e3 * q(gap, 50), "gap_p90_mm": 1e3 * q(gap, 90),
            "within_1mm": float(np.mean(gap <= 1e-3)) if len(gap) else float("nan"),
            "horizontal_contacts": int(horiz.sum()), "gap_median_horizontal_mm": 1e3 * q(gap[horiz], 50),
            "within_1mm_horizontal": float(np.mean(gap[horiz] <= 1e-3)) if horiz.any() else float("nan"),
            "gap_median_tilted_mm": 1e3 * q(gap[~horiz], 50),
            "used": int(used.sum()), "used_gap_p90_mm": 1e3 * q(gap[used], 90),
            "used_within_1mm": float(np.mean(gap[used] <= 1e-3)) if used.any() else float("nan"),
            "u_median_mm": 1e3 * q(cs.uncertainty_m[on], 50),
            "force_median_n": q(cs.force_n[on], 50), "force_p90_n": q(cs.force_n[on], 90),
            "force_max_n": float(cs.force_n[on].max()) if on.any() else float("nan"),
            "drift_mm": 1e3 * s["drift_m"], "drift_deg": s["drift_deg"], "max_drift_mm": 1e3 * s["max_drift_m"],
            "false": s["false_detections"], "detections": s["detections_watched"],
            "steps": ex.steps, "explore_s": ex.wall_s, "band_s": ex.band_s, "total_s": wall}


def main():
    from explore3d.strategy.encircle import force_budget_n

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--object", default="cube")
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS)
    ap.add_argument("--heights", type=int, default=2)
    ap.add_argument("--angles", type=int, default=4)
    ap.add_argument("--normals", type=int, default=4)
    ap.add_argument("--budget", type=float, default=force_budget_n(0.1, 0.5),
                    help="press force, N (default: half the static friction of 0.1 kg at friction 0.5)")
    ap.add_argument("--friction", type=float, default=None, help="the links' friction (default the scene's)")
    ap.add_argument("--mass-error", type=float, default=None, help="the model's mass error (default the scene's)")
    ap.add_argument("--dump", default=None, help="npz of the per-contact figures (last variant)")
    ap.add_argument("--out", required=True, help="JSON lines file (appended)")
    args = ap.parse_args()
    for v in args.variants:
        d = one(args.object, v, args.heights, args.angles, args.normals, args.budget, args.friction, args.mass_error, args.dump)
        with Path(args.out).open("a") as fh:
            fh.write(json.dumps(d) + "\n")
        print(json.dumps(d), flush=True)


if __name__ == "__main__":
    main()
