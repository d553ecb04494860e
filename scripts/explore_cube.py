"""Explore the built-in 80 mm cube (the paper's object), reconstruct it and print the error figures.

    python scripts/explore_cube.py [--mode 3d|planar] [--quick] [--out runs/cube]
"""
from explore_mesh import explore_object, one_line_errors, options

from explore3d import load_object

if __name__ == "__main__":
    args = options(__doc__.splitlines()[0]).parse_args()
    with one_line_errors("explore_cube"):
        explore_object("cube", load_object("cube"), args, args.out or "runs/cube")
