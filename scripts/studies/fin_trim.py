"""The fins the carving leaves, trimmed: each run folder's estimate scored before and after
:func:`explore3d.reconstruction.carve.trim_fins` (issue 43, item 3; BENCHMARKS.md, "Clean meshes
and one progress display").

    explore3d run cube --out DIR/cube0 --noise-seed 0 -q     # ... one folder per seed
    python scripts/studies/fin_trim.py DIR/cube0 DIR/cube1 ... --out fins.jsonl

Each folder is a 3D run's (its ``estimate.obj`` and ``report.json``; the truth is the run's object,
loaded again by name; runs of this package since the trimming already hold a trimmed estimate,
which then comes back unchanged).  One JSON line per folder: volume error and Hausdorff distance
before and after, vertices, vertices more than 3 mm outside the truth, the volume trimmed (m^3)
and the trim's time (s).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path


def one(folder: Path) -> dict:
    import numpy as np
    import trimesh

    from explore3d.geometry.metrics import shape_error
    from explore3d.reconstruction.carve import trim_fins
    from explore3d.world.objects import load_object

    report = json.loads((folder / "report.json").read_text())
    truth = load_object(report["object"])
    est = trimesh.load(folder / "estimate.obj", process=False)
    t0 = time.perf_counter()
    out, trimmed = trim_fins(est)
    dt = time.perf_counter() - t0
    before, after = shape_error(est, truth), shape_error(out, truth)

    def far(m):
        return int((np.abs(truth.nearest.signed_distance(m.vertices)) > 3e-3).sum())

    return {"folder": str(folder), "object": report["object"], "percent": [round(before.percent, 2), round(after.percent, 2)],
            "hausdorff_mm": [round(1e3 * before.hausdorff_m, 2), round(1e3 * after.hausdorff_m, 2)],
            "vertices": [len(est.vertices), len(out.vertices)], "vertices_over_3mm": [far(est), far(out)],
            "trimmed_m3": trimmed, "trim_s": round(dt, 2)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folders", nargs="+", type=Path, help="folders 'explore3d run' wrote (3D)")
    ap.add_argument("--out", required=True, help="JSON lines file (appended)")
    args = ap.parse_args(argv)
    with open(args.out, "a", encoding="utf-8") as f:
        for d in args.folders:
            row = one(d)
            print(json.dumps(row), flush=True)
            f.write(json.dumps(row) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
