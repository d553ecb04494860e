"""Which localised contacts should the table scene's hull take (issue 23, item 1)?  One table
exploration with localised contacts, then the hull rebuilt from the same contacts under several
limits on their stated uncertainty, and from the paper's link points, each scored against the
resting object (BENCHMARKS.md, "Table scene: the hull's input").

    python scripts/studies/table_uncertainty_study.py --object cube --limits 0.5 1 2 3 5 --out /tmp/unc.jsonl
    python scripts/studies/table_uncertainty_study.py --object cube --detector stall --out /tmp/unc.jsonl  # the baseline

The exploration is ``scene_explore_config("table", points="contacts")`` (the table scene's
solver, controller and force budget); only the hull's input changes between rows, so the rows
compare the input, not the exploration's luck.  Per row: the volume error, the number of contacts
taken and their distance from the true surface (the nearest point of the located face segment;
evaluation only).  The exploration's own figures (drift, false detections, wall time) are the
first line.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import pickle
import time
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--object", default="cube")
    ap.add_argument("--limits", type=float, nargs="+", default=[0.5, 1.0, 2.0, 3.0, 5.0],
                    help="uncertainty limits, mm")
    ap.add_argument("--out", required=True, help="JSON lines file")
    ap.add_argument("--dump", help="npz of the contacts (optional)")
    ap.add_argument("--cache", help="pickle of the exploration: read if it exists, else written (rescoring "
                                    "the same exploration without running it again)")
    ap.add_argument("--detector", choices=["stall", "torque"], default=None,
                    help="the contact detector (ControlConfig.detector; default: the table scene's)")
    ap.add_argument("--settle", choices=["press", "hold"], default=None,
                    help="after a detection, settle pressing on at the budget or holding the stopped pose "
                         "(default: the table scene's for the detector)")
    args = ap.parse_args(argv)

    from explore3d.app.pipeline import reconstruct_exploration
    from explore3d.feeling.contacts import contacts_for_hull
    from explore3d.geometry.metrics import shape_error
    from explore3d.geometry.sdf import SignedDistance
    from explore3d.reconstruction.carve import carve
    from explore3d.reconstruction.tabletop import cut_at_table
    from explore3d.strategy.explore import contact_points, rough_bound, wrap_planes
    from explore3d.world.explore import explore
    from explore3d.world.objects import load_object
    from explore3d.world.scene import SceneWatch, scene_explore_config, settle_scene

    cfg = scene_explore_config("table", points="contacts", detector=args.detector)
    if args.settle is not None:
        cfg = dataclasses.replace(cfg, control=dataclasses.replace(cfg.control,
                                                                   press_while_settling=args.settle == "press"))
    mesh = load_object(args.object)
    setup = settle_scene(mesh, cfg.scene, sim=cfg.sim)
    watch = SceneWatch(setup)
    c, r = rough_bound(setup.truth.vertices)
    if args.cache and Path(args.cache).exists():
        ex, summary, wall = pickle.loads(Path(args.cache).read_bytes())
    else:
        t0 = time.perf_counter()
        ex = explore(mesh, "default", cfg, centre=c, radius=r, setup=setup, after_wrap=watch.after_wrap)
        wall = time.perf_counter() - t0
        summary = watch.summary(ex)
        if args.cache:
            Path(args.cache).write_bytes(pickle.dumps((ex, summary, wall)))
    sdf = SignedDistance(setup.truth)
    floor_z = cfg.floor_z(ex.table_z)
    rows = [dict(object=args.object, detector=cfg.control.detector,
                 settle="press" if cfg.control.press_while_settling else "hold", wraps=len(ex.poses), wall_s=round(wall, 1), contacts=int(len(ex.contacts.force_n)),
                 **{k: v for k, v in summary.items() if isinstance(v, (int, float, str))})]

    def gap_of(cs):
        seg = cs.segments
        t = np.linspace(0.0, 1.0, 11)[None, :, None]
        pts = seg[:, :1] + t * (seg[:, 1:] - seg[:, :1])
        return np.abs(sdf(pts.reshape(-1, 3)).reshape(len(seg), -1)).min(axis=1) if len(seg) else np.zeros(0)

    def score(e, label, **extra):
        try:
            hull = reconstruct_exploration(e, c, r)
        except ValueError as exc:
            rows.append(dict(input=label, error=f"no hull: {str(exc).split(';')[0]}", **extra))
            return
        est = carve(hull.mesh, e.swept).mesh
        est = cut_at_table(est, e.table_z)
        err = shape_error(est, setup.truth, seed=0)
        rows.append(dict(input=label, volume_error_pct=round(err.percent, 2), points=int(len(e.points)),
                         **extra))

    for lim in args.limits:
        cs = contacts_for_hull(ex.contacts, cfg, c, r, plane=wrap_planes(ex.poses), max_uncertainty_m=lim * 1e-3)
        cs = dataclasses.replace(cs, used=cs.used & (cs.points[:, 2] > floor_z))
        used = cs.select(cs.used)
        g = gap_of(used)
        e = dataclasses.replace(ex, points=used.points, point_wrap=used.wrap, point_attempt=used.attempt,
                                point_link=used.link)
        score(e, f"contacts <= {lim:g} mm", taken=int(cs.used.sum()),
              gap_median_mm=round(1e3 * float(np.median(g)), 2) if len(g) else None,
              gap_p90_mm=round(1e3 * float(np.quantile(g, 0.9)), 2) if len(g) else None,
              within_1mm=round(float(np.mean(g <= 1e-3)), 3) if len(g) else None)
    lcfg = dataclasses.replace(cfg, points="links")
    P, pw, pa, pl = contact_points(ex.spec, ex.attempts, lcfg)
    score(dataclasses.replace(ex, points=P, point_wrap=pw, point_attempt=pa, point_link=pl, config=lcfg), "links")
    if args.dump:
        cs = ex.contacts
        np.savez(args.dump, gap=gap_of(cs), force=cs.force_n, u=cs.uncertainty_m, sigma_along=cs.sigma_along_m,
                 interval=cs.along_interval_m, sigma=cs.sigma_nm, resid=cs.residual_nm, still=cs.still,
                 self_contact=cs.self_contact, link=cs.link, wrap=cs.wrap, z=cs.points[:, 2])
    with open(args.out, "a") as f:
        for row in rows:
            print(json.dumps(row))
            f.write(json.dumps(row) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
