"""Explore the built-in 80 mm cube (the paper's object), reconstruct it and print the error figures.

    python scripts/explore_cube.py [--mode 3d|planar] [--quick] [--out runs/cube]

--quick: 8 wraps, no probes, into runs/cube-quick unless --out is given.
"""
from explore_mesh import default_out, explore_object, one_line_errors, options

from explore3d import load_object

if __name__ == "__main__":
    args = options(__doc__.splitlines()[0]).parse_args()
    with one_line_errors("explore_cube"):
        explore_object("cube", load_object("cube"), args, default_out("cube", args))
