"""Regenerate objects/<name>.stl: every built-in object of explore3d.world.objects as a binary STL in metres.

Usage: python scripts/make_objects.py [--out objects]

The library builds these meshes in code and never reads the files; they are shipped for
viewers and for tools that want a mesh path.  Public API only.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
try:
    import explore3d  # noqa: F401
except ImportError:  # running from a checkout without installing the package
    sys.path.insert(0, str(REPO))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "objects",
                        help="output folder (default: the repository's objects/)")
    args = parser.parse_args(argv)

    from explore3d.world.objects import BUILTIN_OBJECTS, object_size

    args.out.mkdir(parents=True, exist_ok=True)
    for name, info in BUILTIN_OBJECTS.items():
        mesh = info.builder()
        path = args.out / f"{name}.stl"
        mesh.export(path, file_type="stl")  # trimesh writes binary STL
        size = object_size(mesh)
        print(f"{path}: {len(mesh.faces)} faces, extents {size['extents'].round(4).tolist()} m, "
              f"volume {size['volume']:.4e} m^3")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
