"""Hull the localised contact points and compare with the paper's link points and the ideal skin
(evaluation only), planar.

For each object: one exploration (record=True, a longer settle so each detection has a
quasi-static moment), the pipeline's reconstruction from the link points (the paper's rule), the
contacts localised from the joint torques at the end of each detection's settle (their mid-height
points, with their wrap ids), and the ideal skin (PyBullet's contact points at the same readings);
each point set is hulled the same way (explore3d.reconstruction.hull_input.reconstruct_points) and scored.

    python3 scripts/studies/localise_hull.py --objects cube cylinder --settle 30
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np

from explore3d import ExploreConfig, load_object
from explore3d.app.compare import _column, format_compare
from explore3d.strategy.encircle import ControlConfig
from explore3d.arm.kinematics import gravity_torques
from explore3d.feeling.localise import localise
from explore3d.app.pipeline import run
from explore3d.robot.sensing import SensorConfig
from explore3d.world.skin import ideal_skin


def localised_points(ex, sigma, pos_sigma=0.0):
    spec = ex.spec
    pts, wraps, forces, keys = [], [], [], []
    for wi, (atts, log) in enumerate(zip(ex.attempts, ex.logs)):
        for ai, att in enumerate(atts):
            s0, T = int(log.start_index[ai]), log.base_T[ai]
            for k in np.flatnonzero(att.contact):
                row = s0 + int(att.detect_step[k])
                q, tau = log.q[row], log.tau[row]
                tau_ext = -(tau + gravity_torques(spec, q, T, log.gravity))
                for c in localise(spec, q, tau_ext, T, sigma_nm=sigma, position_sigma_m=pos_sigma).contacts:
                    pts.append(c.point_world)
                    wraps.append(wi)
                    forces.append(c.force_n)
                    keys.append((wi, ai, c.link))
    return np.array(pts).reshape(-1, 3), np.array(wraps, int), np.array(forces), keys


def corrected_points(ex, P, W, keys):
    """The link points of the contact-flagged links, except that a flagged link with a contact
    localised on it (at any settled moment of that attempt) is replaced by its located point(s)."""
    located = {}
    for p, k in zip(P, keys):
        located.setdefault(k, []).append(p)
    keep = np.array([(int(w), int(a), int(l)) not in located for w, a, l in
                     zip(ex.point_wrap, ex.point_attempt, ex.point_link)], bool)
    d = ex.points.shape[1]
    extra = [(p[:d], k[0]) for k, ps in located.items() for p in ps]
    pts = np.concatenate([ex.points[keep], np.array([e[0] for e in extra]).reshape(-1, d)])
    wr = np.concatenate([ex.point_wrap[keep], np.array([e[1] for e in extra], int)])
    return pts, wr


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--objects", nargs="+", default=["cube", "cylinder"])
    ap.add_argument("--sensing", default="default", choices=["default", "ideal"])
    ap.add_argument("--settle", type=int, default=30)
    ap.add_argument("--out")
    a = ap.parse_args()
    sensors = SensorConfig() if a.sensing == "default" else SensorConfig.ideal()
    sigma = max(float(np.hypot(sensors.torque_noise_nm, sensors.torque_resolution_nm / np.sqrt(12.0))), 2.0e-4)
    out = {}
    for obj in a.objects:
        mesh = load_object(obj)
        cfg = ExploreConfig(mode="planar", directions=3, attempts=1, record=True, sensors=sensors,
                            control=dataclasses.replace(ControlConfig(), settle_steps=a.settle))
        t0 = time.perf_counter()
        res = run(mesh, "default", cfg)
        ex = res.exploration
        P, W, F, keys = localised_points(ex, sigma, 1e-4 if a.sensing == "default" else 0.0)
        CP, CW = corrected_points(ex, P, W, keys)
        skin = ideal_skin(ex, mesh)
        cols = [_column("link points (paper)", ex.points, ex.point_wrap, res, 0),
                _column("localised (torques)", P, W, res, 0),
                _column("link points, located links replaced", CP, CW, res, 0),
                _column("ideal skin, loaded", skin.points[skin.loaded], skin.wrap[skin.loaded], res, 0)]
        rep = {"mode": "planar", "columns": [c.to_dict() for c in cols], "wall_s": time.perf_counter() - t0,
               "steps": ex.steps, "n_localised": int(len(P))}
        out[obj] = rep
        print(f"## {obj} ({a.sensing} sensing, settle {a.settle}, {ex.steps} steps, {rep['wall_s']:.0f} s)")
        print(format_compare(rep))
    if a.out:
        json.dump(out, open(a.out, "w"), indent=1)


if __name__ == "__main__":
    main()
