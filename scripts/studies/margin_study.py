"""How thin can PyBullet's collision margin be made while the simulation stays stable?

For every (object, collision_margin) pair asked for, runs the DEFAULT 3D exploration
(``explore3d.app.pipeline.run(load_object(name), "default", ExploreConfig(sim=SimConfig(collision_margin=m),
jobs=JOBS), a=0.05)``) and appends one JSON line to the results file with:

* accuracy: volume error %, IoU, n_contacts, points, exploration wall time;
* tunnelling: signed distance (true mesh, open3d SignedDistance) of every link's inner and outer face
  points (``link_surface_points(spec, att.q, att.T_world_base, 5, 3, ("inner", "outer"))``) at every
  attempt's final configuration: max penetration depth and number of links more than 1 mm inside;
* blow-ups: non-finite joint angles, joints beyond their limits by > 0.1 rad, sweeps that ran out of
  steps (StopReason.TIMEOUT), largest final |q - q_ref|;
* gaps: per contact-flagged joint k, the minimum signed distance of link k's inner-face points
  (the points the hull is built from); and quality.contact_gaps (the inner face of the contact
  link, the most proximal touching link of k..n-1, sampled at 1 mm);
* sha256 of the points and final joint angles (determinism check).

The study in BENCHMARKS.md ("Thin contact margin") ran this script on the code of commit e4a7c35
(ideal sensing, hand-set bands); on the current code the runs use the default sensing and the
measured bands.  Without ``--rereference`` the held joints keep full-torque holds (the baseline
controller); the current default re-references them.

Usage (from the repository root):
    python3 scripts/studies/margin_study.py --objects cube sphere --margins none 1e-3 3e-4 1e-4 3e-5 0 \
        --out margin_study/results.jsonl
Pairs already in the results file are skipped unless --repeat is given (then the run is appended
again, tagged with its repeat index, for the determinism check).
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import sys
import time

import numpy as np


def parse_margin(s: str):
    return None if s.lower() == "none" else float(s)


def margin_key(m) -> str:
    return "none" if m is None else repr(float(m))


def analyse(res, mesh) -> dict:
    from explore3d.strategy.encircle import StopReason
    from explore3d.arm.kinematics import link_surface_points
    from explore3d.world.quality import contact_gaps
    from explore3d.geometry.sdf import SignedDistance

    ex = res.exploration
    spec = ex.spec
    sdf = SignedDistance(mesh)
    atts = [(wi, a) for wi, w in enumerate(ex.attempts) for a in w]
    Q = np.array([a.q for _, a in atts])
    QR = np.array([a.q_ref for _, a in atts])
    Tb = np.array([a.T_world_base for _, a in atts])
    C = np.array([a.contact for _, a in atts])
    wrap_of = np.array([wi for wi, _ in atts])

    # --- blow-ups
    finite = np.isfinite(Q).all(axis=1)
    beyond = np.maximum(Q - spec.joint_upper, spec.joint_lower - Q)  # > 0: beyond a limit, rad
    beyond = np.where(np.isfinite(beyond), beyond, np.inf)
    n_timeout = sum(r is StopReason.TIMEOUT for _, a in atts for r in a.reasons)
    over_steps = [a.steps for _, a in atts]

    # --- tunnelling: every link, inner + outer faces, final configurations
    t0 = time.perf_counter()
    ok = finite
    P = link_surface_points(spec, Q[ok], Tb[ok][:, None], n_along=5, n_height=3, faces=("inner", "outer"))  # (m, n, 30, 3)
    D = sdf(P)  # (m, n, 30) metres, negative inside
    link_min = D.min(axis=2)  # (m, n)
    pen = np.maximum(0.0, -link_min)
    deep = link_min < -1e-3
    deep_wraps = sorted(set(wrap_of[ok][deep.any(axis=1)].tolist()))
    deep_links = [(int(wrap_of[ok][i]), int(j), round(float(-link_min[i, j]) * 1e3, 2))
                  for i, j in zip(*np.nonzero(deep))]

    # --- gaps of the contact-flagged links' inner faces (the hull's points)
    Pin = link_surface_points(spec, Q[ok], Tb[ok][:, None], n_along=5, n_height=3, faces=("inner",))
    Din = sdf(Pin).min(axis=2)  # (m, n)
    g_flag = Din[C[ok]]
    # the hull input points themselves (after the radius and outlier filters)
    from explore3d.reconstruction.hull_input import hull_input_mask
    keep = hull_input_mask(ex.points, ex.point_wrap, res.centre, res.radius)
    dp = sdf(ex.points)
    # quality.contact_gaps: the contact link's inner face at 1 mm pitch
    cg, _, _ = contact_gaps(spec, Q[ok], Tb[ok], C[ok], sdf)
    t_an = time.perf_counter() - t0

    def q(x, p):
        x = np.asarray(x, float)
        return float(np.percentile(x, p)) * 1e3 if x.size else float("nan")

    h = hashlib.sha256()
    h.update(np.ascontiguousarray(ex.points).tobytes())
    h.update(np.ascontiguousarray(Q).tobytes())
    e = res.error
    return {
        "percent_error": float(e.percent), "iou": float(e.iou), "chamfer_mm": float(e.chamfer_m) * 1e3,
        "n_wraps": ex.n_wraps, "n_attempts": len(atts), "n_contacts": int(ex.n_contacts),
        "n_points": int(len(ex.points)), "n_points_used": int(res.n_points_used),
        "n_points_dropped": int((~keep).sum()),
        "explore_wall_s": float(ex.wall_s), "steps": int(ex.steps),
        # blow-ups
        "n_nonfinite_attempts": int((~finite).sum()),
        "max_beyond_limit_rad": float(beyond.max()),
        "n_joints_beyond_0.1rad": int((beyond > 0.1).sum()),
        "n_timeout_sweeps": int(n_timeout), "max_attempt_steps": int(max(over_steps)),
        "max_final_abs_q_minus_qref_rad": float(np.nanmax(np.abs(Q - QR))),
        # tunnelling
        "max_penetration_mm": float(pen.max()) * 1e3,
        "median_attempt_penetration_mm": float(np.median(pen.max(axis=1))) * 1e3,
        "n_links_gt1mm_inside": int(deep.sum()), "n_links_gt0.5mm_inside": int((link_min < -0.5e-3).sum()),
        "wraps_gt1mm_inside": deep_wraps, "deep_links_wrap_link_mm": deep_links[:40],
        "n_points_gt1mm_inside": int((dp < -1e-3).sum()), "n_used_points_gt1mm_inside": int((dp[keep] < -1e-3).sum()),
        "min_used_point_sd_mm": float(dp[keep].min()) * 1e3,
        # gaps
        "flag_gap_median_mm": q(g_flag, 50), "flag_gap_p10_mm": q(g_flag, 10), "flag_gap_p90_mm": q(g_flag, 90),
        "contact_gap_median_mm": q(cg, 50), "contact_gap_p10_mm": q(cg, 10), "contact_gap_p90_mm": q(cg, 90),
        "used_point_sd_median_mm": q(dp[keep], 50),
        "analysis_wall_s": t_an,
        "sha256": h.hexdigest(),
    }


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--objects", nargs="+", required=True)
    ap.add_argument("--margins", nargs="+", required=True, help="metres, or 'none' for PyBullet's defaults")
    ap.add_argument("--out", default="margin_study/results.jsonl")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=0, help="tag (>0: run even if the pair is in the file)")
    ap.add_argument("--directions", type=int, default=None,
                    help="3D plane normals (None: the default 48, i.e. 96 wraps); a stress test uses 72 (144 wraps)")
    ap.add_argument("--rereference", action="store_true",
                    help="ControlConfig(rereference_held=True) instead of the default controller")
    args = ap.parse_args(argv)

    import explore3d
    from explore3d.strategy.encircle import ControlConfig
    from explore3d.strategy.explore import ExploreConfig
    from explore3d.world.objects import load_object
    from explore3d.app.pipeline import run
    from explore3d.core.settings import SimConfig

    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    done = set()
    if os.path.exists(args.out):
        with open(args.out) as fh:
            for line in fh:
                r = json.loads(line)
                done.add((r["object"], r["margin"], r.get("repeat", 0), r.get("directions"),
                          r.get("rereference", False)))
    for name in args.objects:
        for ms in args.margins:
            m = parse_margin(ms)
            key = (name, margin_key(m), args.repeat, args.directions, args.rereference)
            if key in done:
                print("skip", key, flush=True)
                continue
            mesh = load_object(name)
            cfg = ExploreConfig(sim=SimConfig(collision_margin=m), jobs=args.jobs, directions=args.directions,
                                control=ControlConfig(rereference_held=args.rereference))
            t0 = time.perf_counter()
            row = {"object": name, "margin": margin_key(m), "repeat": args.repeat, "jobs": args.jobs,
                   "directions": args.directions, "rereference": args.rereference}
            try:
                res = run(mesh, "default", cfg, a=0.05)
            except Exception as exc:  # a failed run is a result too
                row.update({"error": f"{type(exc).__name__}: {exc}", "total_wall_s": time.perf_counter() - t0})
            else:
                row.update(analyse(res, mesh))
                row["total_wall_s"] = time.perf_counter() - t0
            row["loadavg"] = os.getloadavg()[0]
            row["explore3d"] = explore3d.__file__
            with open(args.out, "a") as fh:
                fh.write(json.dumps(row) + "\n")
            brief = {k: row.get(k) for k in ("object", "margin", "percent_error", "iou", "n_contacts",
                                              "explore_wall_s", "max_penetration_mm", "n_links_gt1mm_inside",
                                              "n_joints_beyond_0.1rad", "n_timeout_sweeps", "flag_gap_median_mm",
                                              "contact_gap_median_mm", "error")}
            print(json.dumps(brief), flush=True)


if __name__ == "__main__":
    sys.exit(main())
