"""Speed benchmark: wall time per wrap, steps/s, real-time factor, and our loop against bare
``stepSimulation`` on the same scene; plus a default 3D reconstruction end to end.

    python scripts/benchmark.py [--skip-3d]

Prints a markdown table for BENCHMARKS.md.  Ratios are measured in one run (shared machines are noisy).
"""
import argparse
import platform
import time

import numpy as np

from explore3d import ArmSpec, ExploreConfig, load_arm, load_object, run
from explore3d.defaults import DEFAULT_A
from explore3d.encircle import ControlConfig, calibrate_band, run_wrap
from explore3d.explore import planar_wrap_poses, rough_bound
from explore3d.sim import ArmSimulation


def bench_wrap(spec, attempts=1, repeats=5):
    """Wall time of one planar wrap around the cube, and a fair bare baseline: the same physics
    steps replayed with the same motor commands (so the same contacts) and nothing else."""
    cube = load_object("cube")
    c, R = rough_bound(cube.vertices)
    pose = planar_wrap_poses(c, R, spec.link_width, 1)[0]
    ctl = ControlConfig()
    band = calibrate_band(spec, ctl, base_transforms=[np.eye(4)])
    with ArmSimulation(spec, cube.vertices, cube.faces) as sim:
        walls, steps = [], []
        for _ in range(repeats):
            s0 = sim.steps
            t0 = time.perf_counter()
            run_wrap(sim, pose.T_world_base, band, attempts=attempts, cfg=ctl)
            walls.append(time.perf_counter() - t0)
            steps.append(sim.steps - s0)
        # Record the commands of one more identical wrap, then replay them with bare PyBullet calls.
        cmds = []
        orig = sim.step

        def recording_step(q_ref, dq_ref=None, forces=None, gravity_compensation=False):
            q = orig(q_ref, dq_ref, forces, gravity_compensation)
            cmds.append((sim._q_ref.tolist(), sim._dq_ref.tolist(), sim._forces.tolist()))
            return q

        sim.step = recording_step
        starts = []
        orig_set_base = sim.set_base

        def recording_set_base(T):
            starts.append(len(cmds))
            orig_set_base(T)

        sim.set_base = recording_set_base
        run_wrap(sim, pose.T_world_base, band, attempts=attempts, cfg=ctl)
        sim.step, sim.set_base = orig, orig_set_base
        # the raw pybullet functions bound to the client: the cheapest way to issue the same calls
        motor, step, arm, joints, pc = sim._motor_array, sim._step_sim, sim.arm, sim.joints, sim._pc
        n = len(joints)
        kp, kd = [sim.config.position_gain] * n, [sim.config.velocity_gain] * n
        t0 = time.perf_counter()
        for i, (q, dq, f) in enumerate(cmds):
            if i in starts:
                sim.set_base(pose.T_world_base)
                sim.reset_joints(np.zeros(n))
            motor(arm, joints, pc, targetPositions=q, targetVelocities=dq, forces=f, positionGains=kp,
                  velocityGains=kd)
            step()
        bare = len(cmds) / (time.perf_counter() - t0)
    wall = float(np.median(walls))
    sps = steps[0] / wall
    return dict(arm=spec.name, links=spec.n_links, attempts=attempts, wall_per_wrap_s=wall, steps=steps[0],
                steps_per_s=sps, realtime_factor=steps[0] * sim.config.timestep / wall, bare_steps_per_s=bare,
                loop_overhead=bare / sps - 1.0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--skip-3d", action="store_true")
    args = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, python {platform.python_version()}")
    print("| arm | links | attempts | wall/wrap (s) | steps | steps/s | real-time factor | replay steps/s | loop overhead |")
    print("|---|---|---|---|---|---|---|---|---|")
    for spec in (ArmSpec(name="small16", n_links=16, link_length=0.02), load_arm("default")):
        for attempts in (1, 4):
            r = bench_wrap(spec, attempts)
            print(f"| {r['arm']} | {r['links']} | {attempts} | {r['wall_per_wrap_s']:.3f} | {r['steps']} | "
                  f"{r['steps_per_s']:.0f} | {r['realtime_factor']:.1f} | {r['bare_steps_per_s']:.0f} | "
                  f"{100 * r['loop_overhead']:.0f}% |")
    if not args.skip_3d:
        cfg = ExploreConfig(jobs=None)
        t0 = time.perf_counter()
        res = run(load_object("cube"), "default", cfg, a=DEFAULT_A)
        print(f"\n3D default on the cube: {res.exploration.n_wraps} wraps, {res.exploration.steps} steps, "
              f"{time.perf_counter() - t0:.1f} s wall, volume error {res.error.percent:.1f}%, IoU {res.error.iou:.3f}")


if __name__ == "__main__":
    main()
