"""Explore the built-in cylinder (the paper's 63 mm radius, 80 mm tall 100-gon prism), reconstruct it
and print the error figures.

    python scripts/explore_cylinder.py [--mode 3d|planar] [--quick] [--out runs/cylinder]

--quick: 8 wraps, no probes, into runs/cylinder-quick unless --out is given.
"""
from explore_mesh import default_out, explore_object, one_line_errors, options

from explore3d import load_object

if __name__ == "__main__":
    args = options(__doc__.splitlines()[0]).parse_args()
    with one_line_errors("explore_cylinder"):
        explore_object("cylinder", load_object("cylinder"), args, default_out("cylinder", args))
