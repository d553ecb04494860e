"""Estimators measured on the same contacts and free space (issue 11, item 5).

    python scripts/studies/estimator_study.py DIR [--label probes] [--objects NAME ...] [--out study.json]

Reads what ``scripts/coverage_bench.py --save`` kept in ``DIR/OBJECT.LABEL/`` (points.ply with the
localised contacts and their normals, free_space.npz, skin.npz) and ``DIR/OBJECT.LABEL.json`` (the
rough bound the robot was told), rebuilds the estimate with each of
:data:`explore3d.reconstruction.estimators.ESTIMATORS` from the localised contacts and from the ideal skin's
points (the implicit surface needs normals: localised only), scores each against the true mesh
(volume error, % of the true volume) and prints a Markdown table with medians.  Evaluation only:
it reads the true mesh to score.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # scripts/: coverage_bench

from coverage_bench import GROUPS, load  # noqa: E402


def study(folder: Path, rec: dict, mesh) -> dict:
    from explore3d.reconstruction.estimators import ESTIMATORS, estimate
    from explore3d.app.export import read_points_ply
    from explore3d.reconstruction.freespace import load_swept
    from explore3d.geometry.metrics import volume_error

    centre, radius = np.array(rec["centre_m"]), float(rec["radius_m"])
    P, props = read_points_ply(folder / "points.ply", with_properties=True)
    N = np.column_stack([props["nx"], props["ny"], props["nz"]])
    swept = load_swept(folder / "free_space.npz") if (folder / "free_space.npz").exists() else []
    skin = np.load(folder / "skin.npz")
    row = {}
    for source, (pts, nrm, wrap) in {"localised": (P, N, props["wrap"]),
                                     "skin": (skin["points"], None, skin["wrap"])}.items():
        for name in ESTIMATORS:
            if name == "implicit" and nrm is None:
                continue
            t0 = time.perf_counter()
            try:
                est = estimate(name, pts, wrap, centre, radius, swept, normals=nrm)
                row[f"{source}/{name}"] = {"percent": 100 * volume_error(est, mesh) / mesh.volume,
                                           "watertight": bool(est.is_watertight), "s": time.perf_counter() - t0}
            except Exception as exc:  # noqa: BLE001 -- record and go on
                row[f"{source}/{name}"] = {"percent": float("nan"), "error": f"{type(exc).__name__}: {exc}"}
    return row


def main():
    from explore3d.reconstruction.estimators import ESTIMATORS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", type=Path)
    ap.add_argument("--label", default="probes")
    ap.add_argument("--objects", nargs="+", default=["concave", "nonconvex"])
    ap.add_argument("--out", type=Path, default=None, help="write the figures as JSON too")
    args = ap.parse_args()
    names = list(dict.fromkeys(n for o in args.objects for n in GROUPS.get(o, (o,))))
    rows = {}
    for name in names:
        folder = args.dir / f"{name}.{args.label}"
        if not (folder / "points.ply").exists():
            print(f"{name}: no saved exploration in {folder}, skipped", file=sys.stderr)
            continue
        rec = json.loads((args.dir / f"{name}.{args.label}.json").read_text())
        rows[name] = study(folder, rec, load(name))
        print(name, {k: round(v["percent"], 2) for k, v in rows[name].items()}, file=sys.stderr, flush=True)
    if args.out:
        args.out.write_text(json.dumps(rows, indent=1))
    cols = [f"{s}/{e}" for s in ("localised", "skin") for e in ESTIMATORS if not (s == "skin" and e == "implicit")]
    print("| object | " + " | ".join(cols) + " |")
    print("|---" * (len(cols) + 1) + "|")
    for name, row in rows.items():
        print(f"| {name} | " + " | ".join(f"{row[c]['percent']:.1f}" if c in row else "n/a" for c in cols) + " |")
    if rows:
        med = [np.nanmedian([row[c]["percent"] for row in rows.values() if c in row]) for c in cols]
        print(f"| **median** (n={len(rows)}) | " + " | ".join(f"{m:.1f}" for m in med) + " |")


if __name__ == "__main__":
    main()
