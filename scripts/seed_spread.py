"""Median and range over seeds of a sweep's figures, per object and setting (Markdown table).

    explore3d sweep cube box --grid noise_seed=0,1,2,3,4 --out runs/seeds --jobs-per-run 2
    python scripts/seed_spread.py runs/seeds

One run is one sample of the arm's contact dynamics (a rounding-level change moves contacts), so a
figure is quoted as the median and range over the seeds a sweep ran (``noise_seed``: the simulated
sensors' noise; ``seed``: the error measure's samples), never as one run.
"""
import json
import sqlite3
import statistics
import sys
from collections import defaultdict
from pathlib import Path


def main(folder: str) -> None:
    db = sqlite3.connect(f"file:{Path(folder) / 'sweep.db'}?mode=ro", uri=True)
    groups = defaultdict(list)
    for obj, settings, status, time_s, report in db.execute(
            "SELECT object, settings, status, time_s, report FROM runs ORDER BY object, settings"):
        s = {k: v for k, v in json.loads(settings).items() if k not in ("noise_seed", "seed")}
        groups[(obj, json.dumps(s, sort_keys=True))].append((status, time_s, json.loads(report or "{}")))
    print("| object | settings | runs (ok) | error % median [min, max] | IoU median | wraps median | time s median |")
    print("|---|---|---|---|---|---|---|")
    for (obj, s), rows in groups.items():
        ok = [r for st, _, r in rows if st == "ok"]
        if not ok:
            print(f"| {obj} | {s} | {len(rows)} (0) | - | - | - | - |")
            continue
        err = [r["percent_error"] for r in ok]
        times = [t for st, t, _ in rows if st == "ok"]
        print(f"| {obj} | {s} | {len(rows)} ({len(ok)}) | {statistics.median(err):.2f} [{min(err):.2f}, {max(err):.2f}] "
              f"| {statistics.median(r['iou'] for r in ok):.3f} | {statistics.median(r['n_wraps'] for r in ok):.0f} "
              f"| {statistics.median(times):.0f} |")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python scripts/seed_spread.py SWEEP_DIR")
    main(sys.argv[1])
