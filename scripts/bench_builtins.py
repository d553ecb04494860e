"""Benchmark: the default 3D run on built-in objects, with the contact-quality figures and a
tunnelling / blow-up check of every attempt's final configuration (evaluation only).

    python scripts/bench_builtins.py [OBJECT ...] [--sensing default|ideal] [--jobs N]

Prints one JSON line per object (volume error, IoU, false detections, contact gap, deepest link
penetration, links more than 1 mm inside, attempts with a joint non-finite or 0.1 rad beyond its
limits, exploration and band times) for BENCHMARKS.md.
"""
import argparse
import json
import os
import platform
import time

import numpy as np

from explore3d import ExploreConfig, load_object, run
from explore3d.arm.kinematics import link_surface_points
from explore3d.world.objects import BUILTIN_OBJECTS
from explore3d.world.quality import contact_quality
from explore3d.geometry.sdf import SignedDistance
from explore3d.robot.sensing import SensorConfig


def measure(obj: str, sensors: SensorConfig, jobs: int) -> dict:
    mesh = load_object(obj)
    t0 = time.perf_counter()
    res = run(mesh, "default", ExploreConfig(jobs=jobs, record=True, sensors=sensors))
    ex = res.exploration
    q = contact_quality(ex, mesh)
    sdf = SignedDistance(mesh)
    deepest, n_inside, blown = 0.0, 0, 0
    for wrap in ex.attempts:
        for att in wrap:
            q_ok = np.isfinite(att.q).all() and (att.q <= ex.spec.joint_upper + 0.1).all() and \
                (att.q >= ex.spec.joint_lower - 0.1).all()
            blown += int(not q_ok)
            P = link_surface_points(ex.spec, att.q, att.T_world_base, 5, 3, ("inner", "outer"))
            sd = sdf(P.reshape(-1, 3)).reshape(ex.spec.n_links, -1).min(axis=1)  # per link, m
            deepest = max(deepest, float(-sd.min()))
            n_inside += int((sd < -1e-3).sum())
    return dict(object=obj, sensing="ideal" if sensors.is_ideal else "default",
                percent_error=round(res.error.percent, 2), iou=round(res.error.iou, 4), n_contacts=ex.n_contacts,
                false_fraction=round(q.false_fraction, 4), n_false=q.n_false,
                gap_median_mm=round(q.gap_true_median_m * 1e3, 3), delay_median_s=round(q.delay_median_s, 4),
                max_penetration_mm=round(max(deepest, 0.0) * 1e3, 3), links_gt1mm_inside=n_inside,
                blown_up_attempts=blown, explore_s=round(ex.wall_s, 1), band_s=round(ex.band_s, 1),
                total_s=round(time.perf_counter() - t0, 1))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("objects", nargs="*", help="built-in names (default: all)")
    ap.add_argument("--sensing", choices=("default", "ideal"), default="default")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    sensors = SensorConfig.ideal() if args.sensing == "ideal" else SensorConfig()
    print(json.dumps(dict(machine=platform.machine(), nproc=os.cpu_count(), python=platform.python_version())),
          flush=True)
    for obj in args.objects or list(BUILTIN_OBJECTS):
        print(json.dumps(measure(obj, sensors, args.jobs)), flush=True)


if __name__ == "__main__":
    main()
