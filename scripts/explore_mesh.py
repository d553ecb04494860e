"""Explore any mesh with the simulated arm, reconstruct it and print the error figures.

    python scripts/explore_mesh.py PATH [--size METRES] [--mode 3d|planar] [--quick] [--out DIR]

PATH is a mesh file (STL, OBJ, PLY, OFF, GLB, ...) or ``pybullet_data:NAME`` (e.g.
``pybullet_data:duck_vhacd.obj --size 0.1``).  The robot is told only the mesh's rough centre and
radius.  Writes the estimate mesh, estimate.urdf, points.ply, pictures and summary.json into
``--out`` (default ``runs/<file name>``, ``runs/<file name>-quick`` with ``--quick``); shows the
progress on stderr (``-q``: none).  The other ``explore_*.py`` scripts share
:func:`options`, :func:`explore_object` and :func:`one_line_errors` from here; everything else is the public API.
"""
import argparse
import contextlib
import json
import sys
from pathlib import Path

from explore3d import RUN_STEPS, ExploreConfig, Progress, load_object, quiet_c_output, run, write_result
from explore3d.core.defaults import DEFAULT_A


def _positive(text):
    v = float(text)
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be > 0; got {text}")
    return v


def options(description: str) -> argparse.ArgumentParser:
    """The options every explore_*.py script takes."""
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--out", help="output folder (default: runs/<name>)")
    p.add_argument("--mode", choices=("3d", "planar"), default="3d", help="3d (default) or planar")
    p.add_argument("--arm", default="default", help="built-in arm (paper, default) or a URDF path")
    p.add_argument("--a", type=_positive, default=DEFAULT_A, help=f"inverse-hull coarseness > 0 (default {DEFAULT_A})")
    p.add_argument("--seed", type=int, default=0, help="seed of the error measure's surface samples")
    p.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    p.add_argument("--quick", action="store_true", help="a small exploration that runs in seconds (planar: 3 directions x 4 attempts; "
                        "3d: 8 planes, 1 angle, no probes: 8 wraps) into its own folder (default runs/<name>-quick)")
    p.add_argument("--no-pictures", action="store_true", help="skip the PNG pictures")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress display (the result line still prints)")
    return p


#: --quick in 3d: 8 plane normals x 1 approach angle and no probe rounds (8 wraps; the default run
#: makes 96 and then up to 90 probe wraps).  Localised contacts need a few dozen readings for a
#: hull; 8 wraps of the cube give about 40 (measured: 27.7% volume error, 14 s of exploration on
#: one core).
QUICK_3D = dict(mode="3d", directions=8, offsets=1, angles=1, attempts=1, probes=None)


def exploration_config(args) -> ExploreConfig:
    """--quick: planar 3 directions x 4 attempts, 3d :data:`QUICK_3D`; planar: 3 directions 90
    degrees apart with 4 attempts (the paper's recommendation); 3d: ExploreConfig's defaults."""
    if args.quick:
        if args.mode == "planar":
            return ExploreConfig(mode="planar", directions=3, attempts=4, jobs=args.jobs)
        return ExploreConfig(**QUICK_3D, jobs=args.jobs)
    if args.mode == "planar":
        return ExploreConfig(mode="planar", directions=3, attempts=4, jobs=args.jobs)
    return ExploreConfig(mode="3d", jobs=args.jobs)


def default_out(name: str, args) -> str:
    """The output folder when --out is not given: ``runs/<name>``, and ``runs/<name>-quick`` for
    --quick (a quick run never overwrites the full run's folder)."""
    return args.out or (f"runs/{name}-quick" if args.quick else f"runs/{name}")


def explore_object(name: str, mesh, args, out) -> dict:
    """Run, write the files and summary.json into ``out``, print one line; returns the summary.
    Shows the command line's progress display on stderr (one bar, or a line per phase when stderr
    is not a terminal; none with ``--quiet``)."""
    with quiet_c_output(), Progress(RUN_STEPS, enabled=not args.quiet, prog=Path(sys.argv[0]).stem) as progress:
        res = run(mesh, args.arm, exploration_config(args), a=args.a, seed=args.seed, progress=progress)
        progress.step("writing")
        files = write_result(res, mesh, out, pictures=not args.no_pictures)
        progress.finish()
    summary = {"object": name, "mode": args.mode, "arm": args.arm, "a": args.a, "seed": args.seed,
               "quick": args.quick, **res.summary(), "files": files + ["summary.json"]}
    Path(out, "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    print(f"{name}: {res.error.percent:.1f} % error, IoU {res.error.iou:.3f}, chamfer {1e3 * res.error.chamfer_m:.1f} mm, "
          f"Hausdorff {1e3 * res.error.hausdorff_m:.1f} mm, {res.exploration.n_wraps} wraps, "
          f"{res.exploration.wall_s:.1f} s -> {out}")
    return summary


@contextlib.contextmanager
def one_line_errors(prog: str):
    """Bad input, no contact, no hull: one line on stderr and exit status 1 instead of a traceback."""
    try:
        yield
    except (ValueError, RuntimeError, OSError) as exc:
        sys.exit(f"{prog}: error: {' '.join(str(exc).split())}")


def main(argv=None):
    p = options(__doc__.splitlines()[0])
    p.add_argument("path", help="mesh file or pybullet_data:NAME")
    p.add_argument("--size", type=_positive, help="rescale so the longest side is SIZE metres")
    args = p.parse_args(argv)
    name = Path(args.path.split(":")[-1]).stem
    with one_line_errors("explore_mesh"):
        explore_object(name, load_object(args.path, size=args.size), args, default_out(name, args))


if __name__ == "__main__":
    main()
