"""Which table-scene wraps touch a resting cube's top face, and where the estimate's error lies
(issue 23, item 2: "measure which wraps touch the top face today").  EVALUATION ONLY: the truth
(the settled cube) is read after the run.

    python scripts/studies/top_face_study.py --object cube --out /tmp/top.json

Per kind of wrap (horizontal, tilted), the contacts found (all and those the hull used) and how
many lie on the top face (within ``--tol`` of the top plane, inside its outline shrunk by the
tolerance); the estimate's top height against the truth's; the volume error split by height
band (below the lowest horizontal wrap, between, above the true top).
"""
from __future__ import annotations

import argparse
import json
from collections import Counter


def main(argv=None) -> int:
    import numpy as np
    import trimesh

    from explore3d.app.pipeline import run
    from explore3d.world.objects import load_object
    from explore3d.world.scene import scene_explore_config, settle_scene

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--object", default="cube")
    ap.add_argument("--tol", type=float, default=0.003, help="m")
    ap.add_argument("--no-search", action="store_true", help="table_top_tol_m=None (no search for the top)")
    ap.add_argument("--yaw", type=float, default=0.0, help="the object turned about the vertical first, degrees")
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    import math

    cfg = scene_explore_config("table", **({"table_top_tol_m": None} if args.no_search else {}))
    mesh = load_object(args.object).copy()
    mesh.apply_transform(trimesh.transformations.rotation_matrix(math.radians(args.yaw), [0, 0, 1]))
    setup = settle_scene(mesh, cfg.scene, sim=cfg.sim)
    res = run(mesh, "default", cfg, setup=setup)
    ex, truth = res.exploration, setup.truth
    top = float(truth.bounds[1, 2])
    lo, hi = truth.bounds[0, :2] + args.tol, truth.bounds[1, :2] - args.tol
    c = ex.contacts

    def on_top(pts):
        pts = np.asarray(pts).reshape(-1, 3)
        return (np.abs(pts[:, 2] - top) < args.tol) & np.all((pts[:, :2] > lo) & (pts[:, :2] < hi), axis=1)

    kinds = np.array(["tilted" if not p.label.startswith("table") else "horizontal" for p in ex.poses])
    wk = kinds[c.wrap]
    used = c.used if c.used is not None else np.ones(len(c.points), bool)
    top_c = on_top(c.points)
    rows = {}
    for k in ("horizontal", "tilted"):
        m = wk == k
        rows[k] = {"wraps": int((kinds == k).sum()), "wraps_with_contact": int(len(set(c.wrap[m]))),
                   "contacts": int(m.sum()), "used": int((m & used).sum()), "on_top": int((m & top_c).sum()),
                   "on_top_used": int((m & top_c & used).sum()),
                   "wraps_touching_top": int(len(set(c.wrap[m & top_c])))}
    hull_pts = np.asarray(ex.points)
    est = res.estimate
    # the error by height band: symmetric difference sampled on a grid
    b = np.vstack([truth.bounds, est.bounds])
    g0, g1 = b.min(axis=0) - 0.002, b.max(axis=0) + 0.002
    step = 0.002
    axes = [np.arange(g0[i], g1[i], step) for i in range(3)]
    P = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    it, ie = truth.contains(P), est.contains(P)
    diff = it ^ ie
    tz = setup.table_z
    from explore3d.arm.urdf import load_arm
    spec = load_arm("default")
    lowest = tz + spec.base_size / 2.0 + cfg.scene.table_clearance + 1.0e-3  # as wrap_poses plans it
    bands = {"below_lowest_wrap": P[:, 2] < lowest, "sides": (P[:, 2] >= lowest) & (P[:, 2] <= top - 0.005),
             "top_5mm": (P[:, 2] > top - 0.005) & (P[:, 2] <= top), "above_top": P[:, 2] > top}
    vol_t = it.sum()
    split = {k: round(100.0 * float((diff & m).sum()) / float(vol_t), 2) for k, m in bands.items()}
    out = {"object": args.object, "yaw_deg": args.yaw, "search": not args.no_search, "percent_error": round(res.error.percent, 2), "truth_top_m": top,
           "estimate_top_m": float(est.bounds[1, 2]), "hull_points": int(len(hull_pts)),
           "hull_points_on_top": int(on_top(hull_pts).sum()),
           "hull_points_above_top_3mm": int((hull_pts[:, 2] > top + args.tol).sum()), "by_kind": rows,
           "error_percent_by_band": split,
           "top_touching_wraps": [ex.poses[w].label for w in sorted(set(c.wrap[top_c]))],
           "kinds_of_top_contacts": dict(Counter(c.kind[top_c].tolist())),
           "top_search": [{"label": p.label, "touched": any(r.value == "contact" for a in att for r in a.reasons)}
                          for p, att in zip(ex.poses, ex.attempts) if p.label.startswith("top search")],
           "wall_s": round(ex.wall_s, 1), "wraps": ex.n_wraps}
    with open(args.out, "w") as fh:
        json.dump(out, fh, indent=1, default=str)
    print(json.dumps(out, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
