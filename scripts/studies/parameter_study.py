"""Parameter study of the inverse convex hull: error against 'a' and link discretisation (paper, V-B).

The paper fixes a = 0.2 and leaves "the optimum values of 'a', and level of discretisation"
as future work.  This script runs the paper's simulated experiment (explore3d.world.simulated:
random straight 8 mm links laid against the object) for 2D objects (80 mm square, 63 mm
100-gon circle, concave L) and 3D objects (80 mm cube, 50 mm sphere, 100-gon cylinder), sweeps
'a' (log-spaced) and the points per link, and writes to --out:

    results.csv   one row per run (object, dim, n_links, a, points_per_link, seed, percent)
    summary.md    mean percent error per object, discretisation and a; best a per object
    error_vs_a.png  percent error against a, one line per discretisation, one panel per object

The simulated contacts are exact (no joint noise, links flush with the surface), so the small
a values that win here may not carry over to measured data: the paper notes that a lower a
"improves the error for the simulated case but increases the error for the experimental
results".  Seeded (seeds 0..--seeds-1); public API only.  Usage:
    python scripts/studies/parameter_study.py [--out runs/parameter_study] [--seeds 2] [--quick]
"""
from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
try:
    import explore3d  # noqa: F401
except ImportError:  # running from a checkout without installing the package
    sys.path.insert(0, str(REPO))


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=Path("runs/parameter_study"), help="output folder")
    p.add_argument("--seeds", type=int, default=2, help="seeds 0..N-1 per setting (default 2)")
    p.add_argument("--a-min", type=float, default=0.02)
    p.add_argument("--a-max", type=float, default=0.5)
    p.add_argument("--a-count", type=int, default=8, help="log-spaced values of a (default 8)")
    p.add_argument("--points-per-link", type=int, nargs="+", default=[2, 3, 5, 9],
                   help="discretisation levels (points per 8 mm link, ends included)")
    p.add_argument("--n-links-2d", type=int, default=320, help="links per 2D run (paper: 320)")
    p.add_argument("--n-links-3d", type=int, default=1500, help="links per 3D run")
    p.add_argument("--quick", action="store_true", help="tiny sweep for a smoke test")
    return p.parse_args(argv)


def study_objects():
    from explore3d.world import objects

    return {
        "square (2D)": objects.square(0.08),
        "circle 100-gon (2D)": objects.regular_polygon(0.063, 100),
        "L (2D, concave)": objects.l_profile(0.08, 0.04),
        "cube (3D)": objects.cube(0.08),
        "sphere (3D)": objects.sphere(0.05, 4),
        "cylinder (3D)": objects.cylinder(0.063, 0.08, 100),
    }


def main(argv=None) -> int:
    args = parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    from explore3d.world.simulated import simulated_case

    if args.quick:
        args.a_count, args.seeds, args.points_per_link, args.n_links_3d = 3, 1, [2, 5], 300
    a_values = np.geomspace(args.a_min, args.a_max, args.a_count)
    args.out.mkdir(parents=True, exist_ok=True)

    rows = []
    t0 = time.perf_counter()
    for name, shape in study_objects().items():
        dim3 = "3D" in name
        n_links = args.n_links_3d if dim3 else args.n_links_2d
        for k in args.points_per_link:
            for a in a_values:
                for seed in range(args.seeds):
                    case = simulated_case(shape, n_links=n_links, link_length=0.008, points_per_link=k,
                                          a=float(a), seed=seed)
                    rows.append({"object": name, "dim": 3 if dim3 else 2, "n_links": n_links, "a": float(a),
                                 "points_per_link": k, "seed": seed, "percent": case.error.percent})
        print(f"{name}: done ({time.perf_counter() - t0:.0f} s)")

    with open(args.out / "results.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)

    names = list(dict.fromkeys(r["object"] for r in rows))
    mean = {}  # (object, k, a) -> mean percent over seeds
    for r in rows:
        mean.setdefault((r["object"], r["points_per_link"], r["a"]), []).append(r["percent"])
    mean = {key: float(np.mean(v)) for key, v in mean.items()}

    lines = ["# Inverse convex hull parameter study", "",
             f"Simulated random 8 mm links; {args.n_links_2d} links in 2D, {args.n_links_3d} in 3D; "
             f"seeds 0..{args.seeds - 1}; percent error = A_err / A_orig (paper eq. 7), mean over seeds.", ""]
    header = "| object | points/link | " + " | ".join(f"a={a:.3g}" for a in a_values) + " |"
    lines += [header, "|" + "---|" * (2 + len(a_values))]
    best_lines = ["", "## Best a per object (lowest mean error over all discretisations)", "",
                  "| object | best a | points/link | percent | percent at a=0.2-nearest |", "|---|---|---|---|---|"]
    a_near = a_values[np.argmin(np.abs(np.log(a_values / 0.2)))]
    for name in names:
        for k in args.points_per_link:
            lines.append(f"| {name} | {k} | " + " | ".join(f"{mean[(name, k, a)]:.2f}" for a in a_values) + " |")
        (bk, ba), bp = min((((k, a), mean[(name, k, a)]) for k in args.points_per_link for a in a_values),
                           key=lambda kv: kv[1])
        near = min(mean[(name, k, a_near)] for k in args.points_per_link)
        best_lines.append(f"| {name} | {ba:.3g} | {bk} | {bp:.2f} | {near:.2f} (a={a_near:.3g}) |")
    (args.out / "summary.md").write_text("\n".join(lines + best_lines) + "\n")

    fig, axes = plt.subplots(2, 3, figsize=(13, 7.5), squeeze=False)
    for ax, name in zip(axes.ravel(), names):
        for k in args.points_per_link:
            ax.plot(a_values, [mean[(name, k, a)] for a in a_values], marker="o", label=f"{k} pts/link")
        ax.axvline(0.2, color="grey", lw=0.8, ls="--")
        ax.set_xscale("log")
        ax.set_xticks(a_values, [f"{a:.2g}" for a in a_values], rotation=45)
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_title(name)
        ax.set_xlabel("a")
        ax.set_ylabel("percent error")
        ax.grid(True, which="both", alpha=0.3)
    axes[0, 0].legend()
    fig.suptitle("Inverse convex hull: error against a (dashed: the paper's a = 0.2)")
    fig.tight_layout()
    fig.savefig(args.out / "error_vs_a.png", dpi=110)
    print("\n".join(best_lines))
    print(f"wrote {args.out}/results.csv, summary.md, error_vs_a.png in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
