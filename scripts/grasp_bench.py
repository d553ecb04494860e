"""Grasp success per object (issue 25): ``explore3d grasp`` on run folders, one Markdown row each.

    python scripts/grasp_bench.py runs/g/cube runs/g/box ... [--n 20] [--seed 0]

Each folder is a default ``explore3d run`` (any run folder works); the grasps are planned on the
estimate, the true mesh, the estimate's convex hull and the first 8 wraps' estimate and executed
on the truth (``explore3d.app.grasp.grasp_run``, which also writes report.json's ``grasp`` entry).
Prints per object: held / planned and the 95% Wilson interval per source, the estimate's rate over
the truth's, and the seconds of planning and executing all four sources.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from explore3d.app.grasp import SOURCES, GraspConfig, grasp_run


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--n", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    print("| object | volume error | " + " | ".join(SOURCES) + " | estimate / truth | seconds |")
    print("|---|---|" + "---|" * len(SOURCES) + "---|---|")
    for run in args.runs:
        e = grasp_run(run, GraspConfig(n=args.n, seed=args.seed), pictures=False)
        report = json.loads((run / "report.json").read_text())
        cells = []
        for name in SOURCES:
            r = e.get(name)
            if r is None:
                cells.append("skipped")
                continue
            lo, hi = r["wilson_95"]
            cells.append(f"{r['held']}/{r['planned']} ({100 * lo:.0f}-{100 * hi:.0f}%)")
        ratio = "-" if e["estimate_over_truth"] is None else f"{e['estimate_over_truth']:.2f}"
        print(f"| {report['object']} | {report['percent_error']:.2f}% | " + " | ".join(cells)
              + f" | {ratio} | {report['timings']['grasp_s']:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
