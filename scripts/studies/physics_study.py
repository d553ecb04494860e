"""The physics measured, not assumed (issue 23, item 4): does the solver keep the arm's joints as
tight beside a resting object as in an empty world?  (BENCHMARKS.md, "Table scene: the solver")

    python scripts/studies/physics_study.py --objects cube cylinder --out /tmp/physics.jsonl

The default arm (5% mass error) lies straight and horizontal ``--gap`` above the object's top
face, clear of it, and swings joints 0 and 5 by 0.3 rad at 0.5 Hz under position control at the
motors' full torque limits for ``--steps`` steps, first in a world with nothing else in it,
then beside the object resting on the table (the table scene, settled), for each solver
setting.  Nothing touches the arm, so a perfect solver gives the empty world's motion exactly.
Per setting: the joints' largest and RMS lag behind their references (mrad), the largest motor
torque read (mN m; both after the first 0.25 s), and how far the motion departs from the empty world's (the largest torque
difference, mN m), plus the object's drift over the swing (mm).  Evaluation only: it reads the
world.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

#: (name, SimConfig overrides): the solver settings compared
SETTINGS = {
    "dantzig": {"solver": "dantzig"},
    "dantzig+cfm1e-7": {"solver": "dantzig", "global_cfm": 1e-7},
    "dantzig+cfm1e-6": {"solver": "dantzig", "global_cfm": 1e-6},
    "dantzig+cfm1e-5": {"solver": "dantzig", "global_cfm": 1e-5},
    "si": {"solver": "si"},
    "si+cfm1e-6": {"solver": "si", "global_cfm": 1e-6},
}


def swing(name: str | None, overrides: dict, steps: int, gap: float) -> tuple[np.ndarray, dict]:
    """Run the swing; return the torques read (steps, n) and the figures."""
    import dataclasses

    from explore3d.arm.urdf import load_arm
    from explore3d.core.settings import SceneConfig, SimConfig
    from explore3d.robot.interface import JointCommand
    from explore3d.world.objects import load_object
    from explore3d.world.scene import object_pose, settle_scene
    from explore3d.world.sim import ArmSimulation

    spec = load_arm("default")
    sim = dataclasses.replace(SimConfig(mass_error=0.05), **overrides)
    mesh = load_object(name or "cube")
    setup = settle_scene(mesh, SceneConfig.named("table"), spec=spec, sim=sim) if name else None
    b = mesh.bounds
    c = b.mean(axis=0)
    T = np.eye(4)
    T[:3, 3] = [c[0] - 0.25, c[1], b[1, 2] + gap + spec.link_height / 2]
    n = spec.n_links
    q0 = np.zeros(n)
    lim = np.array(spec.joint_torques())
    lag, tau = [], []
    with ArmSimulation(spec, config=sim, scene=setup) as world:
        P0 = object_pose(world) if name else None
        world._start(T, q0)
        t0 = time.perf_counter()
        for k in range(steps):
            t = k * sim.timestep
            qr, dqr = q0.copy(), np.zeros(n)
            qr[[0, 5]] = 0.3 * np.sin(np.pi * t)
            dqr[[0, 5]] = 0.3 * np.pi * np.cos(np.pi * t)
            q, _, tq = world._step(JointCommand(q_ref=qr, dq_ref=dqr, torque_limit=lim, tau_ff=np.zeros(n)))
            lag.append(q - qr)
            tau.append(tq)
        wall = time.perf_counter() - t0
        drift = float(np.linalg.norm(object_pose(world)[:3, 3] - P0[:3, 3])) if name else 0.0
    lag, tau = np.array(lag)[60:], np.array(tau)
    return tau, {"lag_max_mrad": 1e3 * float(np.abs(lag).max()),
                 "lag_rms_mrad": 1e3 * float(np.sqrt((lag ** 2).mean())),
                 "torque_max_mNm": 1e3 * float(np.abs(tau[60:]).max()), "drift_mm": 1e3 * drift, "wall_s": wall}


def creep(name: str, overrides: dict, steps: int, fraction: float, torque_nm: float, scene_set: dict | None = None,
          warmup: int = 240) -> dict:
    """Evaluation: the object resting on the table (the arm in the world, straight, 0.25 m away)
    under a steady horizontal push at its centre of mass of ``fraction`` of its static friction
    and a steady torque ``torque_nm`` N m about the vertical, for ``steps`` steps: how far it
    creeps (mm, deg), after ``warmup`` steps untouched (PyBullet's contact manifold between the
    object and the table starts with one point at the face's centre and gathers its corners over
    the first steps: a torque at once spins it about that point).  A solver that holds a resting object keeps both near 0."""
    import dataclasses

    from explore3d.arm.urdf import load_arm
    from explore3d.core.settings import SceneConfig, SimConfig
    from explore3d.robot.interface import JointCommand
    from explore3d.world.objects import load_object
    from explore3d.world.scene import object_pose, pose_drift, settle_scene
    from explore3d.world.sim import ArmSimulation

    spec = load_arm("default")
    sim = dataclasses.replace(SimConfig(mass_error=0.05), **overrides)
    scene = dataclasses.replace(SceneConfig.named("table"), **(scene_set or {}))
    mesh = load_object(name)
    setup = settle_scene(mesh, scene, spec=spec, sim=sim)
    b = mesh.bounds
    c = b.mean(axis=0)
    T = np.eye(4)
    T[:3, 3] = [c[0] - 0.25 - spec.n_links * spec.link_length, c[1], b[1, 2]]
    n = spec.n_links
    lim = np.array(spec.joint_torques())
    mass = float(setup.mass_kg)  # the settled scene's, from the object's volume and the density
    push = fraction * scene.table_friction * mass * 9.81
    hold = JointCommand(q_ref=np.zeros(n), dq_ref=np.zeros(n), torque_limit=lim, tau_ff=np.zeros(n))
    with ArmSimulation(spec, config=sim, scene=setup) as world:
        world._start(T, np.zeros(n))
        for _ in range(warmup):  # the contact manifold between the object and the table fills up
            world._step(hold)
        P0 = object_pose(world)
        cl, body = world.client, world.object
        for _ in range(steps):
            pos = cl.getBasePositionAndOrientation(body)[0]
            cl.applyExternalForce(body, -1, [push, 0.0, 0.0], pos, cl.WORLD_FRAME)
            cl.applyExternalTorque(body, -1, [0.0, 0.0, torque_nm], cl.WORLD_FRAME)
            world._step(hold)
        d, r = pose_drift(P0, object_pose(world))
    return {"object": name, **(scene_set or {}), "mass_kg": mass, "push_n": push, "torque_nm": torque_nm, "steps": steps,
            "creep_mm": 1e3 * d, "creep_deg": float(np.degrees(r))}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", nargs="+", default=["cube", "cylinder"])
    ap.add_argument("--settings", nargs="+", default=list(SETTINGS), choices=list(SETTINGS))
    ap.add_argument("--steps", type=int, default=480, help="physics steps of the swing (240 per second)")
    ap.add_argument("--gap", type=float, default=0.011, help="the links' clearance above the top face, m")
    ap.add_argument("--out", required=True, help="JSON lines file (appended)")
    ap.add_argument("--creep", type=float, nargs=2, metavar=("FRACTION", "TORQUE_NM"),
                    help="instead of the swing: push the resting object with FRACTION of its static friction "
                         "and TORQUE_NM N m about the vertical for --steps steps (creep)")
    ap.add_argument("--scene-set", nargs="*", default=[], metavar="FIELD=VALUE",
                    help="with --creep: SceneConfig fields changed from the table scene's (numbers)")
    args = ap.parse_args()
    scene_set = {k: float(v) for k, v in (a.split("=", 1) for a in args.scene_set)}
    if args.creep:
        for setting in args.settings:
            for name in args.objects:
                row = {"setting": setting, **creep(name, SETTINGS[setting], args.steps, *args.creep, scene_set)}
                with Path(args.out).open("a") as fh:
                    fh.write(json.dumps(row) + "\n")
                print(json.dumps(row), flush=True)
        return
    for setting in args.settings:
        empty, base = swing(None, SETTINGS[setting], args.steps, args.gap)
        rows = [{"setting": setting, "object": None, **base, "departure_mNm": 0.0}]
        for name in args.objects:
            tau, d = swing(name, SETTINGS[setting], args.steps, args.gap)
            rows.append({"setting": setting, "object": name, **d,
                         "departure_mNm": 1e3 * float(np.abs(tau - empty).max())})
        with Path(args.out).open("a") as fh:
            for r in rows:
                fh.write(json.dumps(r) + "\n")
                print(json.dumps(r), flush=True)


if __name__ == "__main__":
    main()
