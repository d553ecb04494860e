"""Explore each concave built-in solid (l_block, u_channel, star_prism) and print their error figures.

    python scripts/explore_concave.py [--mode 3d|planar] [--quick] [--out runs/concave]

The inverse convex hull returns a shape star-shaped about the rough centre, so concavities not
visible from it are filled: these errors show how much.  One sub-folder of --out per object.
"""
from pathlib import Path

from explore_mesh import default_out, explore_object, one_line_errors, options

from explore3d import load_object

CONCAVE = ("l_block", "u_channel", "star_prism")

if __name__ == "__main__":
    args = options(__doc__.splitlines()[0]).parse_args()
    out = Path(default_out("concave", args))
    with one_line_errors("explore_concave"):
        rows = [explore_object(name, load_object(name), args, out / name) for name in CONCAVE]
    print(f"\n{'object':<12} {'error %':>8} {'IoU':>6} {'Hausdorff mm':>13}")
    for r in rows:
        print(f"{r['object']:<12} {r['percent_error']:8.1f} {r['iou']:6.3f} {1e3 * r['hausdorff_m']:13.1f}")
