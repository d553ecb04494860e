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
from explore3d.world.band import cached_band
from explore3d.core.defaults import DEFAULT_A
from explore3d.strategy.encircle import ControlConfig, run_wrap
from explore3d.strategy.explore import planar_wrap_poses, rough_bound
from explore3d.robot.interface import JointCommand, RecordingRobot
from explore3d.world.sim import ArmSimulation


def bench_wrap(spec, attempts=1, repeats=5):
    """Wall time of one planar wrap around the cube, and a fair bare baseline: the same physics
    steps replayed with the same motor commands (so the same contacts), the world's own actuation
    and joint-state calls, and nothing else (no controller, detector or sensing)."""
    cube = load_object("cube")
    c, R = rough_bound(cube.vertices)
    pose = planar_wrap_poses(c, R, spec.link_width, 1)[0]
    ctl = ControlConfig()
    band = cached_band(spec, ctl, planar=True)
    with ArmSimulation(spec, cube.vertices, cube.faces) as world:
        robot = world.robot()
        walls, steps = [], []
        for _ in range(repeats):
            s0 = world.steps
            t0 = time.perf_counter()
            run_wrap(robot, pose.T_world_base, band, attempts=attempts, cfg=ctl)
            walls.append(time.perf_counter() - t0)
            steps.append(world.steps - s0)
        # Record the commands of one more identical wrap through the robot interface, then replay them.
        rec = RecordingRobot(robot)
        run_wrap(rec, pose.T_world_base, band, attempts=attempts, cfg=ctl)
        log = rec.log()
        starts = set(log.start_index.tolist())
        cmds = [JointCommand(log.q_ref[i], log.dq_ref[i], log.torque_limit[i], log.tau_ff[i]) for i in range(log.n_steps)]
        t0 = time.perf_counter()
        for i, cmd in enumerate(cmds):
            if i in starts:
                world._start(pose.T_world_base, log.start_q[0])
            else:
                world._step(cmd)
        bare = (len(cmds) - len(starts)) / (time.perf_counter() - t0)
    wall = float(np.median(walls))
    sps = steps[0] / wall
    return dict(arm=spec.name, links=spec.n_links, attempts=attempts, wall_per_wrap_s=wall, steps=steps[0],
                steps_per_s=sps, realtime_factor=steps[0] * world.config.timestep / wall, bare_steps_per_s=bare,
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
