"""Sweep scaling (issue 12 targets): one sweep of 8 runs, with 1 and 2 local worker processes and
with 2 Ray workers, timed in one session; rows compared (all but the timing columns).

    python scripts/sweep_bench.py [--out runs/sweep_bench] [--objects cube sphere cylinder box]
                                  [--grid a=0.02,0.1] [--set directions=2 ...] [--repeats 1]

Each configuration runs ``explore3d sweep OBJECTS --grid ... --out OUT/<config>-<i>`` in a fresh
folder (one process per run, ``--jobs-per-run 1``); its wall time is the whole command's.  Ray's
start-up (``ray.init(num_cpus=2)`` and ``ray.shutdown()`` in a fresh interpreter) is timed apart.
Prints JSON, then a Markdown table: wall s per configuration, speed-up over 1 worker, Ray against
local with 2 workers, and whether the stored rows are equal.
"""
from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

RAY_START = "import time, ray; t = time.perf_counter(); ray.init(num_cpus=2); print(time.perf_counter() - t); ray.shutdown()"


def sweep(objects, grids, out: Path, workers: int, ray: bool) -> float:
    shutil.rmtree(out, ignore_errors=True)
    cmd = [sys.executable, "-m", "explore3d", "sweep", *objects, "--out", str(out), "--workers", str(workers),
           "--jobs-per-run", "1", "-q"]
    for g in grids:
        cmd += ["--grid", g]
    if ray:
        cmd.append("--ray")
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True)
    return time.perf_counter() - t0


def rows(out: Path) -> list[dict]:
    from explore3d.app.sweep import TIMING_COLUMNS, read_rows

    return sorted(({k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in read_rows(out)),
                  key=lambda r: r["key"])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("runs/sweep_bench"))
    ap.add_argument("--objects", nargs="+", default=["cube", "sphere", "cylinder", "box"])
    ap.add_argument("--grid", action="append", default=None, help="KEY=V1,V2 (default a=0.02,0.1)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=V",
                    help="a fixed setting for every run, e.g. directions=2 (a one-value grid)")
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args()
    grids = (args.grid or ["a=0.02,0.1"]) + args.set
    res = {"objects": args.objects, "grid": grids, "wall_s": {}, "rows_equal": {}}
    p = subprocess.run([sys.executable, "-c", RAY_START], capture_output=True, text=True, check=True)
    res["ray_start_s"] = float(p.stdout.strip().splitlines()[-1])
    configs = [("local-1", 1, False), ("local-2", 2, False), ("ray-2", 2, True)]
    for i in range(args.repeats):
        for name, workers, ray in configs:
            out = args.out / f"{name}-{i}"
            res["wall_s"].setdefault(name, []).append(sweep(args.objects, grids, out, workers, ray))
            print(name, i, f"{res['wall_s'][name][-1]:.1f} s", file=sys.stderr, flush=True)
    ref = rows(args.out / "local-1-0")
    res["n_runs"] = len(ref)
    res["failures"] = sum(1 for r in ref if r.get("status") != "ok")
    for name, _, _ in configs:
        res["rows_equal"][name] = all(rows(args.out / f"{name}-{i}") == ref for i in range(args.repeats))
    print(json.dumps(res, indent=1))
    med = {k: sorted(v)[len(v) // 2] for k, v in res["wall_s"].items()}
    print("\n| configuration | wall s | vs 1 worker | rows equal to local-1 |\n|---|---|---|---|")
    for name, _, _ in configs:
        print(f"| {name} | {med[name]:.1f} | {med['local-1'] / med[name]:.2f}x | {res['rows_equal'][name]} |")
    print(f"\nRay against local, 2 workers: {med['ray-2'] / med['local-2']:.3f} (ray start-up {res['ray_start_s']:.1f} s, "
          f"included in the ray-2 wall time); {res['n_runs']} runs, {res['failures']} failed")


if __name__ == "__main__":
    main()
