"""Contact quality and thickness calibration report: oracle quality figures of the default arm on
the 80 mm cube, the cause of its false detections, and shape errors with and without a contact
thickness calibrated on a known 60 mm ball.

    python scripts/quality_report.py [--mode planar|3d|both] [--jobs 2] [--diagnose-wraps 12]
                                     [--skip-quality] [--skip-calibration] [--json out.json]

Prints markdown tables for BENCHMARKS.md ("Contact quality and thickness calibration").  The
simulation is deterministic; nothing is random.  Planar: ExploreConfig(mode="planar",
directions=3, attempts=4); 3d: ExploreConfig() defaults (whatever they are at the time).
"""
import argparse
import dataclasses
import json
import platform
import subprocess
import time

from explore3d import ExploreConfig, explore, load_object, run
from explore3d.world.calibration import calibrate_thickness
from explore3d.core.defaults import DEFAULT_A
from explore3d.world.quality import contact_quality
from explore3d.world.quality import diagnose_false_detections

A = DEFAULT_A  # inverse-hull coarseness of the scored reconstructions (explore3d.core.defaults)


def config_for(mode: str, jobs: int, **kw) -> ExploreConfig:
    if mode == "planar":
        return ExploreConfig(mode="planar", directions=3, attempts=4, jobs=jobs, **kw)
    return ExploreConfig(jobs=jobs, **kw)


def mm(x):
    return f"{1000 * x:.2f}"


def quality_part(mode: str, jobs: int, diagnose_wraps: int) -> dict:
    cube = load_object("cube")
    t0 = time.perf_counter()
    ex = explore(cube, "default", config_for(mode, jobs, record=True))
    t_explore = time.perf_counter() - t0
    q = contact_quality(ex, cube)
    wraps = list(range(min(diagnose_wraps, ex.n_wraps)))
    d = diagnose_false_detections(ex, cube, wraps=wraps)
    print(f"\n### {mode}: default arm on the 80 mm cube ({ex.n_wraps} wraps, {ex.steps} steps, explore "
          f"{t_explore:.1f} s, quality report {q.wall_s:.1f} s, trajectory stride {q.trajectory_stride})\n")
    print("| figure | value |\n|---|---|")
    rows = [
        ("detections", q.n_detections),
        (f"false (moving chain > {mm(q.false_tol_m)} mm at detection)", f"{q.n_false} ({100 * q.false_fraction:.1f}%)"),
        ("free-space (whole arm > tol)", f"{q.n_free_space} ({100 * q.free_space_fraction:.1f}%)"),
        ("false detections per joint", " ".join(str(v) for v in q.false_joints)),
        ("false: median moving-chain distance (mm)", mm(q.false_distance_median_m)),
        ("delay touch -> detection: median / max (s)", f"{q.delay_median_s:.3f} / {q.delay_max_s:.3f} "
                                                        f"({q.delay_median_steps:.0f} / {q.delay_max_steps} steps, n={q.n_delays})"),
        ("penetration at final configs: max / median (mm)", f"{mm(q.penetration_max_m)} / {mm(q.penetration_median_m)}"),
        ("penetration along trajectories: max (mm)", mm(q.penetration_trajectory_max_m)),
        ("inner-face gap, all detections: median / p90 (mm)", f"{mm(q.gap_median_m)} / {mm(q.gap_p90_m)}"),
        ("inner-face gap, true detections: median / p90 (mm)", f"{mm(q.gap_true_median_m)} / {mm(q.gap_true_p90_m)}"),
        ("link-point gap, true detections: median / p90 (mm)", f"{mm(q.point_gap_median_m)} / {mm(q.point_gap_p90_m)}"),
        ("knock-off held joints: max / median of attempt max (rad)",
         f"{q.knock_off_held_max_rad:.3f} / {q.knock_off_held_median_rad:.3f}"),
        ("knock-off not-yet-swept joints: max (rad)", f"{q.knock_off_distal_max_rad:.3f}"),
        ("final |q - q_ref|: max (rad)", f"{q.knock_off_final_max_rad:.3f}"),
    ]
    for k, v in rows:
        print(f"| {k} | {v} |")
    print(f"\nFalse detections of wraps 0..{len(wraps) - 1} replayed with PyBullet's contact report "
          f"({d.n_false} of {d.n_detections} detections):\n")
    print("| figure | value |\n|---|---|")
    for k, v in [
        ("moving chain touched during the sweep", d.n_touched),
        ("trigger: swept joint's own lag / held joint / distal joint / none",
         f"{d.n_own_lag} / {d.n_held} / {d.n_distal} / {d.n_none}"),
        ("triggering joints (count per joint)", " ".join(str(v) for v in d.trigger_joints)),
        ("held trigger saturated (motor at its torque limit) before the sweep", f"{100 * d.held_saturated_fraction:.0f}%"),
        ("held trigger |q_ref - q| before the sweep: median / max (rad)",
         f"{d.held_error_before_median_rad:.3f} / {d.held_error_before_max_rad:.3f}"),
        ("trigger signal / band: median", f"{d.trigger_ratio_median:.2f}"),
        ("held links' contact force during the sweep: median peak (N)", f"{d.held_force_peak_median_n:.1f}"),
        ("sweeps where that force drops to 0 after contact (chatter)", f"{100 * d.held_force_drops_fraction:.0f}%"),
        ("true detections: own lag / held joint", f"{d.true_n_own_lag} / {d.true_n_held}"),
    ]:
        print(f"| {k} | {v} |")
    return {"mode": mode, "explore_s": t_explore, "quality": q.to_dict(), "diagnosis": d.to_dict()}


def calibration_part(mode: str, jobs: int) -> dict:
    cfg = config_for(mode, jobs)
    cal = calibrate_thickness("default", cfg)
    print(f"\n### {mode}: calibration on the {cal.object} ({cal.n_wraps} wraps, {cal.steps} steps, "
          f"{cal.wall_s:.1f} s)\n")
    print(f"face_offset = **{mm(cal.face_offset_m)} mm** (median of {cal.n_points} contact-link gaps; mean "
          f"{mm(cal.gap_mean_m)}, p10 {mm(cal.gap_p10_m)}, p90 {mm(cal.gap_p90_m)} mm; {cal.n_rejected} flagged "
          f"links farther than {mm(cal.reject_m)} mm left out)\n")
    print(f"| object | error % without | error % with {mm(cal.face_offset_m)} mm | IoU without | IoU with |")
    print("|---|---|---|---|---|")
    out = {"mode": mode, "calibration": cal.to_dict(), "objects": {}}
    for name in (("cube", "cylinder") if mode == "planar" else ("cube",)):
        mesh = load_object(name)
        r0 = run(mesh, "default", cfg, a=A)
        r1 = run(mesh, "default", dataclasses.replace(cfg, face_offset=cal.face_offset_m), a=A)
        print(f"| {name} | {r0.error.percent:.2f} | {r1.error.percent:.2f} | {r0.error.iou:.3f} | {r1.error.iou:.3f} |")
        out["objects"][name] = {"without": r0.error.percent, "with": r1.error.percent,
                                "iou_without": r0.error.iou, "iou_with": r1.error.iou}
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mode", choices=("planar", "3d", "both"), default="both")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--diagnose-wraps", type=int, default=12, help="wraps replayed for the diagnosis")
    ap.add_argument("--skip-quality", action="store_true")
    ap.add_argument("--skip-calibration", action="store_true")
    ap.add_argument("--json", help="also write the figures to this JSON file")
    ap.add_argument("--commit", help="label the report with this commit (default: git rev-parse HEAD here)")
    args = ap.parse_args()
    commit = args.commit
    if not commit:
        try:
            commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                                    text=True).stdout.strip()
        except OSError:
            commit = "?"
    print(f"machine: {platform.machine()}, python {platform.python_version()}, commit {commit or '?'}")
    modes = ("planar", "3d") if args.mode == "both" else (args.mode,)
    report = {"commit": commit, "quality": [], "calibration": []}
    for mode in modes:
        if not args.skip_quality:
            report["quality"].append(quality_part(mode, args.jobs, args.diagnose_wraps))
        if not args.skip_calibration:
            report["calibration"].append(calibration_part(mode, args.jobs))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(report, fh, indent=1, default=float)


if __name__ == "__main__":
    main()
