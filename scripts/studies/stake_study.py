"""Where a default run's estimate can still be wrong: its surface's distance to the nearest hulled
contact against its true distance from the object (issue 24, item 1: "targets by what is at
stake").  EVALUATION ONLY: the truth is read after the run.

    python scripts/studies/stake_study.py --objects bunny torus --out /tmp/stake.json

Per object of the fixed non-convex set (``scripts/nonconvex_set.py``): the README's default run
(ideal scene), then ``--samples`` surface samples of the estimate (seeded) and for each its
distance ``d`` to the nearest contact the hull used and its unsigned distance to the true surface:
the median and 90th percentile of ``d``, the fraction of the surface farther than one link length
(20 mm, today's probe targets' floor, ``ProbeConfig.min_distance_m`` None) from every contact, the
*volume at stake* sum(area x d) as a fraction of the estimate's volume, the same sum with the true
distance (a proxy of the volume error) and the correlation of the two distances.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # scripts/


def one(name: str, samples: int) -> dict:
    import numpy as np
    import trimesh
    from scipy.spatial import cKDTree

    from explore3d.app.pipeline import run
    from nonconvex_set import load

    res = run(load(name), "default")
    est, truth = res.estimate, res.truth
    C = np.asarray(res.hull.points)
    P, _ = trimesh.sample.sample_surface(est, samples, seed=0)
    d = cKDTree(C).query(P)[0]
    true = np.abs(trimesh.proximity.ProximityQuery(truth).signed_distance(P))
    w = est.area / len(P)  # m^2 a sample
    link = res.exploration.spec.link_length
    return {"object": name, "percent_error": round(res.error.percent, 2), "wraps": res.exploration.n_wraps,
            "hulled_contacts": int(len(C)), "d_median_mm": round(1e3 * float(np.median(d)), 2),
            "d_p90_mm": round(1e3 * float(np.percentile(d, 90)), 2),
            "surface_beyond_one_link": round(float((d > link).mean()), 4),
            "stake_over_estimate_volume": round(float(w * d.sum() / est.volume), 3),
            "true_deviation_over_true_volume": round(float(w * true.sum() / truth.volume), 3),
            "true_deviation_within_one_link": round(float(true[d <= link].sum() / true.sum()), 4),
            "correlation_d_true": round(float(np.corrcoef(d, true)[0, 1]), 3)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", nargs="+", default=["bunny", "torus"])
    ap.add_argument("--samples", type=int, default=20000)
    ap.add_argument("--out", required=True, help="JSON file")
    args = ap.parse_args(argv)
    rows = []
    for name in args.objects:
        rows.append(one(name, args.samples))
        print(json.dumps(rows[-1]), flush=True)
    Path(args.out).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
