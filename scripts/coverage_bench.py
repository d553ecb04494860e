"""Coverage benchmark of non-convex objects: explore3d.app.compare per object, one JSON per (object, label).

    python scripts/coverage_bench.py [--objects concave nonconvex | NAME ...] [--out runs/coverage]
                                     [--label default] [--jobs 2] [--encircle straight|curl-back]
                                     [--probes ROUNDS] [--fingers N] [--no-free-space] [--save]

For each object runs :func:`explore3d.app.compare.compare` once (the default 3D exploration, or the
strategy chosen with ``--encircle``, ``--probes``, ``--fingers`` and ``--no-free-space`` as in ``explore3d compare``: link
points, localised contacts, ideal skin all / loaded contacts) and writes ``OUT/OBJECT.LABEL.json``
(written to a temporary file, then renamed).  Files already present are skipped, so a killed run
rerun does only what is missing; a failure (no contact, no hull, ...) is recorded in its file with
its reason and the run goes on.  With ``--save`` the exploration's hull points
(``OUT/OBJECT.LABEL/points.ply``, as ``explore3d run`` writes them), its free space
(``free_space.npz``) and the ideal skin's points (``skin.npz``: points, wrap, loaded) are kept
too, for estimators measured on the same contacts (scripts/studies/estimator_study.py).  Each file also holds a reference, "dense samples": the same
inverse hull (a = DEFAULT_A, about the rough centre) of 5000 points sampled uniformly on the true
surface (seed 0) -- what the estimator could give if the arm touched everywhere.

Then prints a Markdown table of every requested object's file for LABEL (volume errors %, coverage
within 3 / 6 mm, exploration time) with medians over the nonconvex group and over concave +
nonconvex.  Groups: convex, concave (built-ins) and nonconvex (scripts/nonconvex_set.py).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
try:
    import explore3d  # noqa: F401
except ImportError:  # running from a checkout without installing the package
    sys.path.insert(0, str(REPO))
sys.path.insert(0, str(Path(__file__).resolve().parent))  # scripts/: nonconvex_set

from nonconvex_set import NONCONVEX_SET  # noqa: E402

GROUPS = {
    "convex": ("cube", "box", "cylinder", "sphere", "capsule", "cone"),
    "concave": ("l_block", "u_channel", "star_prism"),
    "nonconvex": tuple(NONCONVEX_SET),
}
N_DENSE = 5000


def load(name: str):
    from explore3d import load_object

    if name in NONCONVEX_SET:
        spec, size = NONCONVEX_SET[name]
        return load_object(spec, size=size)
    return load_object(name)


def dense_reference(mesh, centre) -> float:
    """Volume error (%) of the inverse hull of N_DENSE uniform surface samples about ``centre``."""
    import trimesh

    from explore3d.core.defaults import DEFAULT_A
    from explore3d.geometry.hull import inverse_hull
    from explore3d.geometry.metrics import volume_error

    P, _ = trimesh.sample.sample_surface(mesh, N_DENSE, seed=np.random.default_rng(0))
    hull = inverse_hull(P, centre=centre, a=DEFAULT_A)
    return 100.0 * volume_error(hull.shape(), mesh) / mesh.volume


def git_commit() -> str:
    """The short commit of the code measured, "-dirty" when tracked files are modified."""
    def git(*a):
        return subprocess.run(["git", "-C", str(REPO), *a], capture_output=True, text=True).stdout.strip()

    dirty = git("status", "--porcelain", "--untracked-files=no")
    return git("rev-parse", "--short", "HEAD") + ("-dirty" if dirty else "")


def save_exploration(ex, skin, folder: Path) -> None:
    """Keep ``ex``'s hull points, free space and ideal-skin points in ``folder``."""
    from explore3d.reconstruction.freespace import save_swept
    from explore3d.app.report import write_exploration_points

    folder.mkdir(parents=True, exist_ok=True)
    write_exploration_points(ex, folder / "points.ply")
    if ex.swept:
        save_swept(ex.swept, folder / "free_space.npz")
    np.savez_compressed(folder / "skin.npz", points=skin.points, wrap=skin.wrap, loaded=skin.loaded)


def measure(name: str, label: str, config, save: Path | None = None) -> dict:
    import dataclasses

    from explore3d.core.quiet import quiet_c_output
    from explore3d.app.compare import compare_exploration
    from explore3d.world.explore import explore
    from explore3d.strategy.explore import rough_bound
    from explore3d.world.skin import ideal_skin

    mesh = load(name)
    centre, radius = rough_bound(mesh.vertices)
    rec = {"object": name, "label": label, "commit": git_commit(), "argv": sys.argv[1:], "centre_m": centre.tolist(), "radius_m": radius,
           "centre_inside": bool(mesh.contains([centre])[0]), "volume_over_hull": mesh.volume / mesh.convex_hull.volume}
    try:
        rec["dense_samples_percent"] = dense_reference(mesh, centre)
    except Exception as exc:  # noqa: BLE001 -- record and go on
        rec["dense_samples_percent"], rec["dense_samples_error"] = float("nan"), f"{type(exc).__name__}: {exc}"
    t0 = time.perf_counter()
    try:
        with quiet_c_output():
            ex = explore(mesh, "default", dataclasses.replace(config, points="contacts"), centre=centre, radius=radius)
            skin = ideal_skin(ex, mesh)
            rec["report"] = compare_exploration(ex, mesh, centre, radius, skin=skin)
            if save is not None:
                save_exploration(ex, skin, save)
    except Exception as exc:  # noqa: BLE001 -- record and go on
        rec["error"] = f"{type(exc).__name__}: {exc}"
        rec["traceback"] = traceback.format_exc()
    rec["wall_s"] = time.perf_counter() - t0
    return rec


def write_json(path: Path, rec: dict) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    with os.fdopen(fd, "w") as f:
        json.dump(rec, f, indent=1)
    os.replace(tmp, path)


def table(recs: list[dict]) -> str:
    """Markdown rows per object, then medians over the nonconvex group and concave + nonconvex."""
    pc = lambda v: "n/a" if not np.isfinite(v) else f"{v:.1f}"  # noqa: E731

    def values(r):
        if "error" in r:
            return [np.nan] * 4 + [r["dense_samples_percent"]] + [np.nan] * 5
        rep = r["report"]
        c = {col["name"]: col for col in rep["columns"]}
        loc, skin = c["localised contacts"], c["ideal skin, all contacts"]
        return [c["link points (paper)"]["percent_error"], loc["percent_error"], skin["percent_error"],
                c["ideal skin, loaded contacts"]["percent_error"], r["dense_samples_percent"],
                100 * loc["coverage_3mm"], 100 * loc["coverage_6mm"], 100 * skin["coverage_3mm"],
                100 * skin["coverage_6mm"], rep["explore_s"]]

    def row(name, v):
        return (f"| {name} | " + " | ".join(pc(x) for x in v[:5]) + f" | {pc(v[5])} / {pc(v[6])} | "
                f"{pc(v[7])} / {pc(v[8])} | {pc(v[9])} |")

    out = ["| object | link points | localised | skin all | skin loaded | dense samples | localised cov. 3/6 mm | "
           "skin-all cov. 3/6 mm | explore s |", "|---" * 9 + "|"]
    vals = {r["object"]: values(r) for r in recs}
    for r in recs:
        out.append(row(r["object"] + (f" (failed: {r['error']})" if "error" in r else ""), vals[r["object"]]))
    for group, members in (("nonconvex", GROUPS["nonconvex"]), ("concave+nonconvex",
                                                                 GROUPS["concave"] + GROUPS["nonconvex"])):
        V = [vals[n] for n in members if n in vals]
        if V:
            with np.errstate(all="ignore"):
                out.append(row(f"**median {group}** (n={len(V)})", np.nanmedian(np.array(V), axis=0)))
    return "\n".join(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", nargs="+", default=["concave", "nonconvex"],
                    help="object names and/or groups: " + ", ".join(GROUPS) + " (default: concave nonconvex)")
    ap.add_argument("--out", type=Path, default=Path("runs/coverage"), help="output folder")
    ap.add_argument("--label", default="default", help="name of the method/setting measured (default 'default')")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes per exploration (default 2)")
    ap.add_argument("--encircle", choices=("straight", "curl-back"), default="straight",
                    help="how each attempt encircles (default straight)")
    ap.add_argument("--probes", type=int, default=None, help="rounds of probes (default: ExploreConfig's, 3)")
    ap.add_argument("--fingers", type=int, default=None, help="finger probes per round (default: ExploreConfig's, 12)")
    ap.add_argument("--no-free-space", dest="no_free_space", action="store_true",
                    help="neither record the swept space nor carve (implies --probes 0)")
    ap.add_argument("--save", action="store_true",
                    help="keep each exploration's points, free space and skin points in OUT/OBJECT.LABEL/")
    args = ap.parse_args()
    import dataclasses

    from explore3d.app.settings import explore_config

    opts = {"jobs": args.jobs, "encircle": args.encircle}
    if args.probes is not None or args.no_free_space:
        opts["probes"] = 0 if args.no_free_space else args.probes
    if args.fingers is not None:
        opts["fingers"] = args.fingers
    config = explore_config(opts)
    if args.no_free_space:
        config = dataclasses.replace(config, free_space=False)
    names = list(dict.fromkeys(n for o in args.objects for n in GROUPS.get(o, (o,))))
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    for name in names:
        path = args.out / f"{name}.{args.label}.json"
        if path.exists():
            print(f"{name}: {path} present, skipped", file=sys.stderr, flush=True)
            continue
        print(f"{name}: exploring ...", file=sys.stderr, flush=True)
        rec = measure(name, args.label, config, args.out / f"{name}.{args.label}" if args.save else None)
        write_json(path, rec)
        print(f"{name}: {rec.get('error', 'done')} ({rec['wall_s']:.0f} s)", file=sys.stderr, flush=True)
    print(f"total {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    print(table([json.loads((args.out / f"{n}.{args.label}.json").read_text()) for n in names]))


if __name__ == "__main__":
    main()
