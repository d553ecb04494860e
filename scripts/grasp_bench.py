"""Grasp success per object (issue 25): ``explore3d grasp`` on run folders, one Markdown row each.

    python scripts/grasp_bench.py runs/g/cube runs/g/box ... [--n 20] [--seed 0] [--friction MU]
        [--grip-force N] [--density KG_M3]

Each folder is a default ``explore3d run`` (any run folder works); the grasps are planned on the
estimate, the true mesh, the estimate's convex hull and the first 8 wraps' estimate and executed
on the truth (``explore3d.app.grasp.grasp_run``, which also writes report.json's ``grasp`` entry).
Prints per object: held / planned, the 95% Wilson interval and the median push (how far closing
moved the object, mm) per source, the estimate's rate over the truth's, and the seconds of planning
and executing all four sources.  The gripper and the
execution take ``explore3d grasp``'s options (``explore3d.app.cli.grasp_config``).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from explore3d.app.cli import grasp_config
from explore3d.app.grasp import SOURCES, grasp_run


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--n", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--friction", type=float, default=None)
    ap.add_argument("--grip-force", dest="grip_force", type=float, default=None)
    ap.add_argument("--density", type=float, default=None)
    ap.add_argument("--reuse", action="store_true",
                    help="tabulate the grasp entry report.json already holds (explore3d run --grasp N) "
                         "instead of grading again")
    args = ap.parse_args(argv)
    print("| object | volume error | " + " | ".join(SOURCES) + " | estimate / truth | seconds |")
    print("|---|---|" + "---|" * len(SOURCES) + "---|---|")
    for run in args.runs:
        if not args.reuse:
            grasp_run(run, grasp_config(args), pictures=False)
        report = json.loads((run / "report.json").read_text())
        e = report["grasp"]
        cells = []
        for name in SOURCES:
            r = e.get(name)
            if r is None:
                cells.append("skipped")
                continue
            lo, hi = r["wilson_95"]
            push = "" if r.get("push_median_m") is None else f", push {1e3 * r['push_median_m']:.1f} mm"
            cells.append(f"{r['held']}/{r['planned']} ({100 * lo:.0f}-{100 * hi:.0f}%){push}")
        ratio = "-" if e["estimate_over_truth"] is None else f"{e['estimate_over_truth']:.2f}"
        print(f"| {report['object']} | {report['percent_error']:.2f}% | " + " | ".join(cells)
              + f" | {ratio} | {report['timings']['grasp_s']:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
