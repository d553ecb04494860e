"""The fixed set of non-convex meshes the coverage benchmarks measure (BENCHMARKS.md, issue 11).

    python scripts/nonconvex_set.py            # (re)write objects/nonconvex/*.stl and list the set

Fixed before the first measurement and not to be changed afterwards: three organic meshes from
pybullet_data, scaled so the longest bounding-box side is 0.1 m, and three blocky prisms built
here (metres, bounding box centred at the origin).  ``load(name)`` returns the mesh.
"""
from __future__ import annotations

import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
try:
    import explore3d  # noqa: F401
except ImportError:  # running from a checkout without installing the package
    sys.path.insert(0, str(REPO))

from shapely.geometry import Polygon, box
from shapely.ops import unary_union

OUT = REPO / "objects" / "nonconvex"

#: name -> load_object spec and size (longest side, m; None: as built)
NONCONVEX_SET = {
    "bunny": ("pybullet_data:bunny.obj", 0.1),
    "duck": ("pybullet_data:duck.obj", 0.1),
    "torus": ("pybullet_data:torus/torus_textured.obj", 0.1),
    "t_prism": (str(OUT / "t_prism.stl"), None),
    "cross_prism": (str(OUT / "cross_prism.stl"), None),
    "stairs": (str(OUT / "stairs.stl"), None),
}


def _profiles() -> dict[str, tuple[Polygon, float]]:
    """Blocky profiles (x-y, metres) and extrusion depths along z."""
    t = unary_union([box(-0.045, 0.01, 0.045, 0.04), box(-0.015, -0.04, 0.015, 0.01)])  # T: bar 30 mm, stem 30 mm
    cross = unary_union([box(-0.045, -0.015, 0.045, 0.015), box(-0.015, -0.045, 0.015, 0.045)])  # plus, arms 30 mm
    stairs = Polygon([(-0.045, -0.0375), (0.045, -0.0375), (0.045, -0.0125), (0.015, -0.0125), (0.015, 0.0125),
                      (-0.015, 0.0125), (-0.015, 0.0375), (-0.045, 0.0375)])  # three 30 x 25 mm steps
    return {"t_prism": (t, 0.06), "cross_prism": (cross, 0.05), "stairs": (stairs, 0.06)}


def write() -> None:
    from explore3d.world.objects import _extrude

    OUT.mkdir(parents=True, exist_ok=True)
    for name, (poly, depth) in _profiles().items():
        mesh = _extrude(poly, depth)
        mesh.apply_translation(-(mesh.bounds[0] + mesh.bounds[1]) / 2.0)
        mesh.export(OUT / f"{name}.stl")


def load(name: str):
    from explore3d import load_object

    spec, size = NONCONVEX_SET[name]
    return load_object(spec, size=size)


if __name__ == "__main__":
    write()
    for name in NONCONVEX_SET:
        m = load(name)
        print(f"{name:12s} {len(m.faces):5d} faces  extents {1e3 * m.extents.round(4)} mm  volume {m.volume * 1e6:7.1f} cm^3  "
              f"volume / convex hull {m.volume / m.convex_hull.volume:.3f}")
