"""Contact localisation from proprioception against PyBullet's true contacts (evaluation only).

Runs wraps through the robot interface, recording every reading (RecordingRobot) while an
observing wrapper (evaluation only) keeps PyBullet's arm-object contact points after every physics
step.  At chosen moments of each attempt it localises the contacts from the reading alone
(explore3d.feeling.localise, joint angles and motor torques) and scores them against the contacts the
reading reflects (the physics step ``delay_steps`` earlier).

Moments: ``settle`` = the last settle step after each detection (Attempt.detect_step[k]);
``detect`` = the detection step itself (the chain still moving).

    python3 scripts/studies/localise_study.py --objects cube cylinder --mode planar --out /tmp/loc_planar.json
    python3 scripts/studies/localise_study.py --summarise /tmp/loc_planar.json
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import pickle
import sys
import time

import numpy as np

from explore3d import ExploreConfig, load_arm, load_object
from explore3d.world.band import cached_band
from explore3d.strategy.encircle import run_wrap
from explore3d.strategy.explore import rough_bound, wrap_poses
from explore3d.arm.kinematics import gravity_torques, link_transforms
from explore3d.feeling.localise import INNER_SIDE, INNER_SIDE_ROUNDED, KINDS, inverse_dynamics, localise
from explore3d.robot.interface import JointCommand, JointReading, RecordingRobot, Robot
from explore3d.robot.sensing import SensorConfig
from explore3d.world.sim import ArmSimulation

RADIUS_OK = 3.0e-3
LOADED = 1.0e-3


class ObservingRobot(Robot):
    """Passes the robot interface through; after every physics step keeps PyBullet's contacts
    (evaluation only): per step a list of (link, positionOnA (3,), normal on B (3,), normal force)."""

    def __init__(self, world, robot):
        self._world, self._robot = world, robot
        self.spec, self.dt, self.gravity = robot.spec, robot.dt, robot.gravity
        self.motions: list = []

    @property
    def base_pose(self):
        return self._robot.base_pose

    def _observe(self):
        w = self._world
        rows = []
        for c in w.client.getContactPoints(bodyA=w.arm, bodyB=w.object):
            if 0 <= c[3] < self.spec.n_links:
                rows.append((int(c[3]), np.array(c[5]), np.array(c[7]), float(c[9])))
        self.motions[-1].append(rows)

    def start(self, T_world_base, q0) -> JointReading:
        r = self._robot.start(T_world_base, q0)
        self.motions.append([])
        self._observe()
        return r

    def step(self, command: JointCommand) -> JointReading:
        r = self._robot.step(command)
        self._observe()
        return r


def score_moment(spec, T, q, tau_ext, truth, sigma, **loc_kw):
    """Localise at one moment and score against the true contacts ``truth`` (list of rows)."""
    Tinv = np.linalg.inv(T)
    t0 = time.perf_counter()
    loc = localise(spec, q, tau_ext, T, sigma_nm=sigma, **loc_kw)
    solve_s = time.perf_counter() - t0
    # true contacts per link: points (base frame) and force; the link's centre of pressure
    by_link: dict = {}
    Tl = link_transforms(spec, q, T)
    for link, p, nrm, f in truth:
        pb = Tinv[:3, :3] @ p + Tinv[:3, 3]
        by_link.setdefault(link, []).append((pb, f, Tl[link, :3, :3].T @ nrm, Tl[link, :3, :3].T @ (p - Tl[link, :3, 3])))
    true_links = {}
    for link, rows in by_link.items():
        P = np.array([r[0] for r in rows])
        F = np.array([r[1] for r in rows])
        cands = list(P)
        if F.sum() > 0:
            cands.append((F[:, None] * P).sum(0) / F.sum())
        true_links[link] = {"cands": np.array(cands), "force": float(F.sum()), "loaded": bool(F.max() >= LOADED),
                            "n_points": len(rows), "normals_link": [r[2].round(3).tolist() for r in rows],
                            "points_link": [(1e3 * r[3]).round(2).tolist() for r in rows], "forces": F.tolist()}
    found = []
    for c in loc.contacts:
        pb = Tinv[:3, :3] @ c.point_world + Tinv[:3, 3]
        rec = {"interval_mm": [1e3 * c.along_interval_m[0], 1e3 * c.along_interval_m[1]],
               "link": c.link, "kind": c.kind, "point_link_mm": (1e3 * c.point_link).round(2).tolist(), "force": c.force_n, "sigma_along": c.sigma_along_m,
               "err2d": None, "err3d": None, "err2d_any": None}
        if c.link in true_links:
            C = true_links[c.link]["cands"]
            rec["err2d"] = float(np.min(np.linalg.norm(C[:, :2] - pb[:2], axis=1)))
            rec["err3d"] = float(np.min(np.linalg.norm(C - pb, axis=1)))
            # distance to the face segment across the height at the located position
            a_, b_ = (Tinv[:3, :3] @ x + Tinv[:3, 3] for x in c.segment_world)
            t_ = np.clip((C - a_) @ (b_ - a_) / ((b_ - a_) @ (b_ - a_)), 0.0, 1.0)
            rec["err_seg"] = float(np.min(np.linalg.norm(C - (a_ + t_[:, None] * (b_ - a_)), axis=1)))
        allc = [v["cands"] for v in true_links.values()]
        if allc:
            A = np.concatenate(allc)
            rec["err2d_any"] = float(np.min(np.linalg.norm(A[:, :2] - pb[:2], axis=1)))
        found.append(rec)
    truth_out = []
    for link, v in sorted(true_links.items()):
        hit = [f for f in found if f["link"] == link and f["err2d"] is not None and f["err2d"] <= RADIUS_OK]
        truth_out.append({"link": link, "force": v["force"], "loaded": v["loaded"], "n_points": v["n_points"],
                          "recalled": bool(hit), "normals_link": v["normals_link"], "points_link_mm": v["points_link"],
                          "forces": v["forces"]})
    return {"found": found, "truth": truth_out, "rms_residual": loc.residual_nm, "solve_s": solve_s}


def run(obj_name, mode, sensing, directions, angles, attempts, settle, hold_bias=0.0):
    spec = load_arm("default")
    mesh = load_object(obj_name)
    sensors = SensorConfig() if sensing == "default" else SensorConfig.ideal()
    cfg = ExploreConfig(mode=mode, directions=directions, angles=angles, attempts=attempts, sensors=sensors)
    # the band is calibrated with the default controller; a longer settle only changes holds
    band = cached_band(spec, cfg.control, cfg.sim, sensors, mode == "planar")
    control = dataclasses.replace(cfg.control, settle_steps=settle, hold_bias=hold_bias)
    poses = wrap_poses(spec, cfg, *rough_bound(mesh.vertices))
    # sigma of each external torque: the sensor's noise and quantisation (plus a floor for the model)
    sig = float(np.hypot(sensors.torque_noise_nm, sensors.torque_resolution_nm / np.sqrt(12.0)))
    sigma = max(sig, 2.0e-4)
    d = sensors.delay_steps
    out = []
    t0 = time.perf_counter()
    with ArmSimulation(spec, np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64), cfg.sim) as world:
        for wi, pose in enumerate(poses):
            robot = world.robot(sensors)
            robot.reseed((0, wi))
            obs = ObservingRobot(world, robot)
            rec = RecordingRobot(obs)
            atts = run_wrap(rec, pose.T_world_base, band, attempts=attempts, base_step=cfg.base_step, cfg=control)
            log = rec.log()
            for ai, att in enumerate(atts):
                s0 = int(log.start_index[ai])
                T = log.base_T[ai]
                for k in np.flatnonzero(att.contact):
                    for moment, step in (("settle", int(att.detect_step[k])),
                                         ("detect", int(att.detect_step[k]) - settle)):
                        row = s0 + step
                        q, tau, dq = log.q[row], log.tau[row], log.dq[row]
                        static = -(tau + gravity_torques(spec, q, T, log.gravity))
                        ddq = (dq - log.dq[row - 1]) / log.dt  # backward difference (causal)
                        dyn = inverse_dynamics(spec, q, dq, ddq) + static
                        truth = obs.motions[ai][max(step - d, 0)]
                        out.append({"object": obj_name, "mode": mode, "sensing": sensing, "settle": settle,
                                    "wrap": wi, "attempt": ai, "joint": int(k), "moment": moment, "T": T, "q": q,
                                    "hold_bias": hold_bias,
                                    "static": static, "dyn": dyn, "truth": truth,
                                    "max_dq": float(np.max(np.abs(dq))), "sigma": sigma})
            print(f"{obj_name} {mode} {sensing} settle={settle} wrap {wi + 1}/{len(poses)} "
                  f"{time.perf_counter() - t0:.0f}s steps={world.steps}", file=sys.stderr, flush=True)
    return out, time.perf_counter() - t0, world.steps


def score_all(moments, pos_sigma=0.0, **loc_kw):
    """Localise every stored moment (static and +ID variants) and score it."""
    spec = load_arm("default")
    out = []
    for m in moments:
        loc_kw["position_sigma_m"] = pos_sigma if m["sensing"] == "default" else 0.0
        for variant, key in ((m["moment"], "static"), (m["moment"] + "+ID", "dyn")):
            r = score_moment(spec, m["T"], m["q"], m[key], m["truth"], m["sigma"], **loc_kw)
            r["hold_bias"] = m.get("hold_bias", 0.0)
            r.update({k: m[k] for k in ("object", "mode", "sensing", "settle", "wrap", "attempt", "joint", "max_dq",
                                        "sigma")})
            r["moment"] = variant
            out.append(r)
    return out


def pct(x, p):
    return float(np.percentile(x, p)) if len(x) else float("nan")


def summarise(rows, key=("object", "mode", "sensing", "settle", "moment")):
    if any(r.get("hold_bias", 0.0) for r in rows):
        rows = [dict(r, settle=f"{r['settle']} (bias {r.get('hold_bias', 0.0):g})") for r in rows]
    groups: dict = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in key), []).append(r)
    lines = ["| object | mode | sensing | settle | moment | moments | max dq median (rad/s) | found | in-plane median / p90 (mm) "
             "| 3D median / p90 (mm) | 3D to segment median / p90 (mm) | precision 3 mm | recall 3 mm: all | >= 1e-3 N | >= 0.1 N | >= 1 N | any-link in-plane median / p90 (mm) |",
             "|---" * 17 + "|"]
    for g, rs in sorted(groups.items()):
        found = [f for r in rs for f in r["found"]]
        e2 = np.array([f["err2d"] for f in found if f["err2d"] is not None])
        e3 = np.array([f["err3d"] for f in found if f["err3d"] is not None])
        es = np.array([f["err_seg"] for f in found if f.get("err_seg") is not None])
        ea = np.array([f["err2d_any"] for f in found if f["err2d_any"] is not None])
        prec = np.mean([f["err2d"] is not None and f["err2d"] <= RADIUS_OK for f in found]) if found else float("nan")
        tl = [t for r in rs for t in r["truth"]]
        def rec(fmin):
            sel = [t["recalled"] for t in tl if (t["loaded"] if fmin == LOADED else t["force"] >= fmin)]
            return f"{100 * np.mean(sel):.1f}% ({len(sel)})" if sel else "-"
        dq = np.median([r["max_dq"] for r in rs])
        lines.append(f"| {' | '.join(str(x) for x in g)} | {len(rs)} | {dq:.3f} | {len(found)} | "
                     f"{1e3 * pct(e2, 50):.2f} / {1e3 * pct(e2, 90):.2f} | {1e3 * pct(e3, 50):.2f} / {1e3 * pct(e3, 90):.2f} | "
                     f"{1e3 * pct(es, 50):.2f} / {1e3 * pct(es, 90):.2f} | {100 * prec:.1f}% | {rec(0.0)} | {rec(LOADED)} | {rec(0.1)} | {rec(1.0)} | "
                     f"{1e3 * pct(ea, 50):.2f} / {1e3 * pct(ea, 90):.2f} |")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--objects", nargs="+", default=["cube", "cylinder"])
    ap.add_argument("--mode", default="planar")
    ap.add_argument("--sensing", nargs="+", default=["default", "ideal"])
    ap.add_argument("--directions", type=int, default=3)
    ap.add_argument("--angles", type=int, default=1)
    ap.add_argument("--attempts", type=int, default=1)
    ap.add_argument("--settle", nargs="+", type=int, default=[3])
    ap.add_argument("--hold-bias", type=float, default=0.0, help="ControlConfig.hold_bias, rad")
    ap.add_argument("--moments", help="simulate and store the moments here (.pkl)")
    ap.add_argument("--score", nargs="*", help="score stored moments (.pkl files)")
    ap.add_argument("--kinds", default="rounded", choices=["inner-side", "rounded", "all"])
    ap.add_argument("--chi2", type=float, default=25.0)
    ap.add_argument("--pos-sigma", type=float, default=0.0,
                    help="localise(position_sigma_m=...) for default-sensing moments, metres")
    ap.add_argument("--only", nargs="*", default=[], help="score only moments with these key=value (e.g. settle=30)")
    ap.add_argument("--out", help="scored rows (.json)")
    ap.add_argument("--summarise", nargs="*", help="tables of scored rows (.json files)")
    a = ap.parse_args()
    if a.summarise:
        rows = [r for p in a.summarise for r in json.load(open(p))["rows"]]
        print(summarise(rows))
        return
    if a.score is None:
        moments, meta = [], []
        for obj in a.objects:
            for s in a.sensing:
                for st in a.settle:
                    m, wall, steps = run(obj, a.mode, s, a.directions, a.angles, a.attempts, st, a.hold_bias)
                    moments += m
                    meta.append({"object": obj, "sensing": s, "settle": st, "wall_s": wall, "steps": steps})
        with open(a.moments, "wb") as f:
            pickle.dump({"meta": meta, "args": vars(a), "moments": moments}, f)
        print(json.dumps(meta))
        return
    moments = []
    for p in a.score:
        with open(p, "rb") as f:
            moments += pickle.load(f)["moments"]
    for kv in a.only:
        k, v = kv.split("=")
        moments = [m for m in moments if str(m[k]) == v]
    kinds = {"inner-side": INNER_SIDE, "rounded": INNER_SIDE_ROUNDED, "all": KINDS}[a.kinds]
    t0 = time.perf_counter()
    rows = score_all(moments, kinds=kinds, chi2_gain=a.chi2, pos_sigma=a.pos_sigma)
    wall = time.perf_counter() - t0
    if a.out:
        json.dump({"args": vars(a), "score_s": wall, "rows": rows}, open(a.out, "w"))
    print(f"localised {len(rows)} moments in {wall:.1f} s ({1e3 * wall / max(len(rows), 1):.0f} ms each)")
    print(summarise(rows))


if __name__ == "__main__":
    main()
