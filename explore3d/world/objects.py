"""Object library: the paper's test objects, more solids, and a loader for mesh files.

Units are metres everywhere.  Every builder returns a closed (watertight), consistently and
outward-wound ``trimesh.Trimesh`` in its own frame, with its axis-aligned bounding box centred
at the origin and prism/axis directions along +z.  The meshes are built by code, so the
library needs no data files at run time; ``scripts/make_objects.py`` writes the same meshes to
``objects/<name>.stl`` for viewers and other tools.

``load_object`` accepts a built-in name, a path to any mesh file trimesh reads, or
``"pybullet_data:NAME"``.  It never moves the mesh: the result is in the file's own frame
(after an optional scaling about the file's origin), so reconstructions overlay the input
mesh in any viewer.

Planar helpers (``square``, ``regular_polygon``, ``cross_section``) return shapely polygons
in metres, exterior wound counter-clockwise, for the 2D (prism) case of the paper.
"""
from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import trimesh
from shapely.geometry import MultiPolygon, Polygon
from shapely.geometry.polygon import orient

from explore3d.core.validate import check_positive, check_vector

__all__ = [
    "BUILTIN_OBJECTS",
    "MeshError",
    "ObjectInfo",
    "box",
    "builtin_object_names",
    "capsule",
    "cone",
    "cross_section",
    "cube",
    "cylinder",
    "l_block",
    "l_profile",
    "load_object",
    "object_size",
    "regular_polygon",
    "sphere",
    "square",
    "star_polygon",
    "star_prism",
    "u_channel",
    "u_profile",
]

logger = logging.getLogger(__name__)

#: Prefix of a ``load_object`` spec naming a file in pybullet's bundled data directory.
PYBULLET_DATA_PREFIX = "pybullet_data:"


class MeshError(ValueError):
    """A mesh could not be loaded as a closed volume; the message says what and how to fix it."""


# ----------------------------------------------------------------------------------------------
# Planar shapes (metres, CCW exterior, centred on the origin)
# ----------------------------------------------------------------------------------------------


def square(side: float = 0.08) -> Polygon:
    """Axis-aligned square of edge ``side`` metres centred at the origin (the paper's 80 mm cube)."""
    h = check_positive(side, "side") / 2.0
    return orient(Polygon([(-h, -h), (h, -h), (h, h), (-h, h)]), 1.0)


def regular_polygon(radius: float = 0.063, sections: int = 100) -> Polygon:
    """Regular ``sections``-gon with vertices on a circle of ``radius`` metres about the origin.

    The first vertex is at angle 0 (on +x).  The defaults are the paper's cylinder cross-section
    (63 mm radius approximated by a 100-sided polygon); the vertex set equals the one of
    ``cylinder(radius, ..., sections)`` for even ``sections``.  Area = sections/2 r^2 sin(2 pi/sections).
    """
    r = check_positive(radius, "radius")
    n = _check_sections(sections)
    ang = 2.0 * np.pi * np.arange(n) / n
    return orient(Polygon(np.column_stack([r * np.cos(ang), r * np.sin(ang)])), 1.0)


def l_profile(size: float = 0.08, thickness: float = 0.04) -> Polygon:
    """L-shaped polygon: a ``size`` x ``size`` square with a (size-thickness)^2 corner notch.

    Both arms are ``thickness`` wide; the bounding box is centred at the origin; the notch is at
    +x +y.  Area = size^2 - (size - thickness)^2 (4.8e-3 m^2 for the defaults).
    """
    s = check_positive(size, "size")
    t = check_positive(thickness, "thickness")
    if t >= s:
        raise ValueError(f"thickness must be smaller than size; got thickness={t}, size={s}")
    h = s / 2.0
    pts = [(-h, -h), (h, -h), (h, -h + t), (-h + t, -h + t), (-h + t, h), (-h, h)]
    return orient(Polygon(pts), 1.0)


def u_profile(width: float = 0.08, height: float = 0.08, wall: float = 0.02) -> Polygon:
    """U-shaped polygon: ``width`` x ``height`` rectangle with a slot open towards +y.

    The slot is (width - 2 wall) wide and (height - wall) deep, leaving two side walls and a
    floor ``wall`` thick.  Bounding box centred at the origin.
    Area = width height - (width - 2 wall)(height - wall) (4.0e-3 m^2 for the defaults).
    """
    w = check_positive(width, "width")
    h = check_positive(height, "height")
    t = check_positive(wall, "wall")
    if 2 * t >= w or t >= h:
        raise ValueError(f"wall must satisfy 2*wall < width and wall < height; got wall={t}, width={w}, height={h}")
    x, y = w / 2.0, h / 2.0
    pts = [(-x, -y), (x, -y), (x, y), (x - t, y), (x - t, -y + t), (-x + t, -y + t), (-x + t, y), (-x, y)]
    return orient(Polygon(pts), 1.0)


def star_polygon(outer_radius: float = 0.05, inner_radius: float = 0.025, points: int = 5) -> Polygon:
    """Star with ``points`` tips on a circle of ``outer_radius`` and notches on ``inner_radius`` (metres).

    The first tip is on +y; centred on the origin (the star's centre, not its bounding box).
    Area = points * outer_radius * inner_radius * sin(pi / points) (2*points triangles fanned
    from the centre), 3.67e-3 m^2 for the defaults.
    """
    ro = check_positive(outer_radius, "outer_radius")
    ri = check_positive(inner_radius, "inner_radius")
    if ri >= ro:
        raise ValueError(f"inner_radius must be smaller than outer_radius; got {ri} >= {ro}")
    n = int(points)
    if n != points or n < 3:
        raise ValueError(f"points must be an integer >= 3; got {points!r}")
    ang = np.pi / 2.0 + np.pi * np.arange(2 * n) / n
    rad = np.where(np.arange(2 * n) % 2 == 0, ro, ri)
    return orient(Polygon(np.column_stack([rad * np.cos(ang), rad * np.sin(ang)])), 1.0)


# ----------------------------------------------------------------------------------------------
# Solids (metres, watertight, outward wound, bounding box centred at the origin)
# ----------------------------------------------------------------------------------------------


def cube(side: float = 0.08) -> trimesh.Trimesh:
    """Cube of edge ``side`` metres (the paper's 80 mm box), 12 triangles.  Volume side^3."""
    s = check_positive(side, "side")
    return trimesh.creation.box(extents=[s, s, s])


def box(extents=(0.10, 0.06, 0.04)) -> trimesh.Trimesh:
    """Axis-aligned box with edge lengths ``extents`` (3,) metres.  Volume = product of extents."""
    ext = check_vector(extents, "extents", 3)
    for i, e in enumerate(ext):
        check_positive(e, f"extents[{i}]")
    return trimesh.creation.box(extents=ext)


def cylinder(radius: float = 0.063, height: float = 0.08, sections: int = 100) -> trimesh.Trimesh:
    """Right prism over a regular ``sections``-gon of circumradius ``radius``, axis z, length ``height`` (m).

    The paper's cylinder has a 63 mm radius and is approximated by a 100-sided polygon; the
    height (80 mm, like the cube) is ours, since the paper works in the plane.  The mesh is
    exactly ``regular_polygon(radius, sections)`` extruded over z in [-height/2, height/2]:
    volume = sections/2 r^2 sin(2 pi/sections) height.
    """
    r = check_positive(radius, "radius")
    h = check_positive(height, "height")
    return trimesh.creation.cylinder(radius=r, height=h, sections=_check_sections(sections))


def sphere(radius: float = 0.05, subdivisions: int = 4) -> trimesh.Trimesh:
    """Icosphere of ``radius`` metres (every vertex on the sphere), 20 * 4**subdivisions triangles.

    Inscribed convex polyhedron: its volume is below 4/3 pi r^3 and above 4/3 pi d^3, d the
    smallest distance of a face plane from the centre (d^2 = r^2 - rho^2, rho the largest
    triangle circumradius).
    """
    r = check_positive(radius, "radius")
    k = int(subdivisions)
    if k != subdivisions or k < 0:
        raise ValueError(f"subdivisions must be an integer >= 0; got {subdivisions!r}")
    return trimesh.creation.icosphere(subdivisions=k, radius=r)


def capsule(radius: float = 0.03, height: float = 0.10, count=(32, 32)) -> trimesh.Trimesh:
    """Capsule (cylinder with hemispherical caps) along z; ``height`` is the overall tip-to-tip length (m).

    Needs height >= 2 radius; the straight part is height - 2 radius long.  Note trimesh's own
    ``creation.capsule`` takes the straight length instead.  Vertices lie on the true surface,
    so the volume is below pi r^2 (h - 2r) + 4/3 pi r^3.  ``count`` is (longitude, latitude)
    resolution.
    """
    r = check_positive(radius, "radius")
    h = check_positive(height, "height")
    if h < 2 * r:
        raise ValueError(f"capsule height (tip to tip) must be >= 2*radius; got height={h}, radius={r}")
    return trimesh.creation.capsule(height=h - 2 * r, radius=r, count=list(count))


def cone(radius: float = 0.05, height: float = 0.08, sections: int = 64) -> trimesh.Trimesh:
    """Right pyramid over a regular ``sections``-gon of circumradius ``radius``; apex on +z.

    Bounding box centred at the origin: base at z = -height/2, apex at z = +height/2.
    Volume = 1/3 * sections/2 r^2 sin(2 pi/sections) * height (exact for this polygonal cone).
    """
    r = check_positive(radius, "radius")
    h = check_positive(height, "height")
    mesh = trimesh.creation.cone(radius=r, height=h, sections=_check_sections(sections))
    mesh.apply_translation([0.0, 0.0, -h / 2.0])
    return mesh


def l_block(size: float = 0.08, thickness: float = 0.04, depth: float = 0.08) -> trimesh.Trimesh:
    """Concave L-shaped prism: ``l_profile(size, thickness)`` extruded ``depth`` metres along z.

    Defaults: 80 x 80 mm L with 40 mm wide arms, 80 mm deep: volume 4.8e-3 * 0.08 = 3.84e-4 m^3
    (the cube minus a 40 x 40 x 80 mm notch).
    """
    return _extrude(l_profile(size, thickness), check_positive(depth, "depth"))


def u_channel(width: float = 0.08, height: float = 0.08, wall: float = 0.02, depth: float = 0.08) -> trimesh.Trimesh:
    """Concave U-channel prism: ``u_profile(width, height, wall)`` extruded ``depth`` metres along z.

    Defaults: 80 x 80 mm outline, 20 mm walls, a 40 mm wide 60 mm deep slot, 80 mm long:
    volume (6.4e-3 - 2.4e-3) * 0.08 = 3.2e-4 m^3.
    """
    return _extrude(u_profile(width, height, wall), check_positive(depth, "depth"))


def star_prism(outer_radius: float = 0.05, inner_radius: float = 0.025, points: int = 5,
               height: float = 0.04) -> trimesh.Trimesh:
    """Concave star prism: ``star_polygon(...)`` extruded ``height`` metres along z.

    Defaults: 5-pointed star, tips on a 50 mm circle, notches on 25 mm, 40 mm thick:
    volume 5 * 0.05 * 0.025 * sin(pi/5) * 0.04 = 1.469e-4 m^3.  Only z is centred on the
    bounding box; in xy the star's own centre is at the origin.
    """
    return _extrude(star_polygon(outer_radius, inner_radius, points), check_positive(height, "height"))


def _extrude(poly: Polygon, depth: float) -> trimesh.Trimesh:
    mesh = trimesh.creation.extrude_polygon(poly, depth)
    mesh.apply_translation([0.0, 0.0, -depth / 2.0])
    trimesh.repair.fix_normals(mesh)
    return mesh


def _check_sections(sections) -> int:
    n = int(sections)
    if n != sections or n < 3:
        raise ValueError(f"sections must be an integer >= 3; got {sections!r}")
    return n


# ----------------------------------------------------------------------------------------------
# Registry
# ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ObjectInfo:
    """A built-in object: its registry ``name``, a one-line ``description``, and a ``builder``
    taking no arguments and returning a fresh mesh (metres, own frame)."""

    name: str
    description: str
    builder: Callable[[], trimesh.Trimesh]


BUILTIN_OBJECTS: dict[str, ObjectInfo] = {
    info.name: info
    for info in (
        ObjectInfo("cube", "80 mm cube (paper, Fig. 4)", cube),
        ObjectInfo("cylinder", "63 mm radius 100-gon prism, 80 mm tall (paper, Fig. 4)", cylinder),
        ObjectInfo("sphere", "50 mm radius icosphere, 4 subdivisions", sphere),
        ObjectInfo("box", "100 x 60 x 40 mm box", box),
        ObjectInfo("capsule", "30 mm radius capsule, 100 mm tip to tip", capsule),
        ObjectInfo("cone", "50 mm radius 64-gon cone, 80 mm tall", cone),
        ObjectInfo("l_block", "concave L prism, 80 mm outline, 40 mm arms, 80 mm deep", l_block),
        ObjectInfo("u_channel", "concave U channel, 80 mm outline, 20 mm walls, 80 mm long", u_channel),
        ObjectInfo("star_prism", "concave 5-point star prism, 50/25 mm radii, 40 mm thick", star_prism),
    )
}


def builtin_object_names() -> list[str]:
    """Names of the built-in objects, in registry order."""
    return list(BUILTIN_OBJECTS)


def object_size(mesh: trimesh.Trimesh) -> dict:
    """Size summary of ``mesh`` (metres, mesh frame).

    Returns a dict with ``extents`` (3,) bounding-box edge lengths [m], ``bbox_centre`` (3,)
    [m], ``volume`` [m^3] and ``bounding_radius`` [m]: the largest distance of a vertex from
    the bounding-box centre.
    """
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.vertices) == 0:
        raise ValueError(f"object_size needs a non-empty trimesh.Trimesh; got {type(mesh).__name__}")
    lo, hi = mesh.bounds
    centre = (lo + hi) / 2.0
    return {
        "extents": hi - lo,
        "bbox_centre": centre,
        "volume": float(mesh.volume),
        "bounding_radius": float(np.linalg.norm(mesh.vertices - centre, axis=1).max()),
    }


# ----------------------------------------------------------------------------------------------
# Loading
# ----------------------------------------------------------------------------------------------


def load_object(spec, scale: float | None = None, size: float | None = None) -> trimesh.Trimesh:
    """Load an object as a closed, outward-wound triangle mesh.

    Parameters
    ----------
    spec
        A built-in name (see ``builtin_object_names()``), a path (str or PathLike) to any mesh
        file trimesh reads (STL, OBJ, PLY, OFF, GLB, ...), or ``"pybullet_data:NAME"`` for a
        file in ``pybullet_data.getDataPath()`` (e.g. ``"pybullet_data:duck_vhacd.obj"``).
        Scenes (several meshes, e.g. OBJ groups) are concatenated with their transforms
        applied.  Files are taken to be in metres.
    scale
        Multiply all coordinates by this factor, about the file's origin.
    size
        Rescale, about the file's origin, so the longest bounding-box side is ``size`` metres.
        Pass ``scale`` or ``size``, not both.

    Returns
    -------
    trimesh.Trimesh with vertices (n, 3) in metres, in the file's frame after scaling (the mesh
    is never re-centred).

    Repair: a mesh that is not a closed, consistently wound, positive-volume surface is
    repaired by (1) merging duplicate vertices, including ones split only by texture
    coordinates or normals, (2) dropping degenerate and duplicate faces, (3) making the face
    winding consistent and outward, per connected body, and (4) filling holes of 3 or 4 edges.
    If the result is a closed volume it is returned and a warning saying what was repaired is
    logged; otherwise ``MeshError`` is raised.

    Raises
    ------
    MeshError (a ValueError) for a missing or unreadable file, a file without triangles, an
    unknown built-in name or pybullet_data file, or a mesh that is not a closed volume after
    repair.  ValueError for a non-positive ``scale``/``size`` or both given.
    """
    if scale is not None and size is not None:
        raise ValueError("pass scale or size to load_object, not both")
    if scale is not None:
        scale = check_positive(scale, "scale")
    if size is not None:
        size = check_positive(size, "size")

    if isinstance(spec, str) and spec in BUILTIN_OBJECTS:
        mesh = BUILTIN_OBJECTS[spec].builder()
        label = spec
    else:
        path = _resolve_path(spec)
        label = path.name
        mesh = _read_mesh(path)
        _repair(mesh, label)

    if scale is not None:
        mesh.apply_scale(scale)
    if size is not None:
        longest = float(mesh.extents.max())
        if not longest > 0:
            raise MeshError(f"{label} has zero extent; cannot rescale it to size {size} m")
        mesh.apply_scale(size / longest)
    return mesh


def _resolve_path(spec) -> Path:
    if isinstance(spec, str) and spec.startswith(PYBULLET_DATA_PREFIX):
        import pybullet_data  # start-up: pybullet's data package, only for pybullet_data: names

        name = spec[len(PYBULLET_DATA_PREFIX):]
        root = Path(pybullet_data.getDataPath())
        path = root / name
        if not name or not path.is_file():
            raise MeshError(
                f"pybullet_data has no file {name!r} (looked in {root}); "
                "pass a file name such as pybullet_data:duck_vhacd.obj or pybullet_data:bunny.obj"
            )
        return path
    if not isinstance(spec, (str, os.PathLike)):
        raise MeshError(f"object spec must be a built-in name, a path or 'pybullet_data:NAME'; got {type(spec).__name__}")
    path = Path(spec)
    if path.is_file():
        return path
    if isinstance(spec, str) and not path.suffix and os.sep not in spec and "/" not in spec:
        raise MeshError(
            f"unknown object {spec!r}: not a built-in name (valid: {', '.join(BUILTIN_OBJECTS)}) "
            "nor an existing mesh file"
        )
    raise MeshError(f"mesh file not found: {path}; check the path or use a built-in name")


def _read_mesh(path: Path) -> trimesh.Trimesh:
    try:
        # unprocessed first: trimesh's processing silently drops the faces of non-finite vertices
        # (the truth would become another solid); processed below, as trimesh.load(path) would
        loaded = trimesh.load(str(path), process=False)
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise MeshError(f"cannot read {path.name} as a mesh ({type(exc).__name__}: {exc}); "
                        "pass a mesh file trimesh reads (STL, OBJ, PLY, OFF, GLB, ...)") from None
    parts = loaded.geometry.values() if isinstance(loaded, trimesh.Scene) else [loaded]
    for part in parts:
        if isinstance(part, trimesh.Trimesh):
            bad = int((~np.isfinite(np.asarray(part.vertices, dtype=float))).any(axis=1).sum())
            if bad:
                raise MeshError(f"{path.name} has {bad} vertices with a non-finite (NaN or inf) coordinate; "
                                "fix or remove them in the file (a mesh of finite coordinates in metres)")
            part.process()
    if isinstance(loaded, trimesh.Scene):
        if len(loaded.geometry) == 0:
            raise MeshError(f"{path.name} contains no triangles (empty file or not a mesh format trimesh "
                            "understands); pass a triangle mesh file")
        meshes = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh)]
        if not meshes:
            raise MeshError(f"{path.name} contains no triangle meshes (only "
                            f"{sorted({type(g).__name__ for g in loaded.geometry.values()})}); pass a triangle mesh file")
        loaded = trimesh.util.concatenate(meshes)
    if not isinstance(loaded, trimesh.Trimesh):
        raise MeshError(f"{path.name} holds a {type(loaded).__name__}, not a triangle mesh; pass a triangle mesh file")
    if len(loaded.faces) == 0:
        raise MeshError(f"{path.name} contains no triangles; pass a non-empty triangle mesh file")
    return loaded


def _open_edge_count(mesh: trimesh.Trimesh) -> int:
    return len(trimesh.grouping.group_rows(mesh.edges_sorted, require_count=1))


def _is_closed_volume(mesh: trimesh.Trimesh) -> bool:
    return bool(mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0)


def _repair(mesh: trimesh.Trimesh, label: str) -> None:
    """Repair ``mesh`` in place (see ``load_object``); log what changed or raise MeshError."""
    if _is_closed_volume(mesh):
        return
    done = []
    nv = len(mesh.vertices)
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    if len(mesh.vertices) < nv:
        done.append(f"merged {nv - len(mesh.vertices)} duplicate vertices")
    nf = len(mesh.faces)
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.update_faces(mesh.unique_faces())
    mesh.remove_unreferenced_vertices()
    if len(mesh.faces) < nf:
        done.append(f"removed {nf - len(mesh.faces)} degenerate/duplicate faces")
    before = mesh.faces.copy()
    trimesh.repair.fix_winding(mesh)
    trimesh.repair.fix_inversion(mesh, multibody=True)
    flipped = int(np.any(mesh.faces != before, axis=1).sum())
    if flipped == len(before):
        done.append("turned the inside-out surface outward (reversed all faces)")
    elif flipped:
        done.append(f"flipped the winding of {flipped} faces to make it consistent and outward")
    nf = len(mesh.faces)
    trimesh.repair.fill_holes(mesh)
    if len(mesh.faces) > nf:
        done.append(f"filled holes with {len(mesh.faces) - nf} faces")
        trimesh.repair.fix_normals(mesh, multibody=True)  # orient the new faces like their neighbours

    if not mesh.is_watertight:
        open_edges = _open_edge_count(mesh)
        what = f"{open_edges} open edges" if open_edges else "non-manifold edges"
        raise MeshError(f"{label} is not a closed volume ({what}) after repair; "
                        "close the holes or pass a watertight mesh")
    if not mesh.is_winding_consistent:
        raise MeshError(f"{label} has inconsistent face winding after repair (non-orientable or "
                        "self-overlapping surface); pass a clean watertight mesh")
    if not mesh.volume > 0:
        raise MeshError(f"{label} encloses no positive volume after repair (volume {mesh.volume:.3g} m^3); "
                        "pass a solid mesh")
    logger.warning("%s was not a closed, outward-wound volume; repaired: %s", label,
                   "; ".join(done) if done else "nothing changed")


# ----------------------------------------------------------------------------------------------
# Sections
# ----------------------------------------------------------------------------------------------


def cross_section(mesh: trimesh.Trimesh, z: float = 0.0) -> Polygon | MultiPolygon:
    """Planar section of ``mesh`` by the plane at height ``z`` metres with normal +z.

    Returns the region inside the mesh on that plane, in the mesh's x, y coordinates (metres),
    exterior CCW: a shapely Polygon, or a MultiPolygon if the plane cuts several disjoint
    regions.  The ring has a vertex wherever the plane crosses a mesh edge, so triangulated
    side faces add collinear points (``.simplify(1e-12)`` removes them).  Raises ValueError if
    the plane misses the mesh.
    """
    if not isinstance(mesh, trimesh.Trimesh):
        raise ValueError(f"cross_section needs a trimesh.Trimesh; got {type(mesh).__name__}")
    z = float(z)
    if not np.isfinite(z):
        raise ValueError(f"z must be finite; got {z}")
    section = mesh.section(plane_origin=[0.0, 0.0, z], plane_normal=[0.0, 0.0, 1.0])
    zlo, zhi = mesh.bounds[:, 2]
    if section is None:
        raise ValueError(f"plane z={z} m does not cut the mesh (its z range is [{zlo:.6g}, {zhi:.6g}] m)")
    to_plane = np.eye(4)
    to_plane[2, 3] = -z
    planar, _ = section.to_2D(to_2D=to_plane)
    polys = [orient(p, 1.0) for p in planar.polygons_full if p is not None and p.area > 0]
    if not polys:
        raise ValueError(f"plane z={z} m cuts the mesh in no closed region (z range [{zlo:.6g}, {zhi:.6g}] m)")
    if len(polys) == 1:
        return polys[0]
    return MultiPolygon(polys)


#: Radius of the default calibration ball, metres (distinct from every evaluation object: the
#: built-in sphere is 50 mm, the cylinder 63 mm, the cube 80 mm; within the default arm's reach:
#: its 377 mm equator is shorter than the 480 mm arm).
CALIBRATION_SPHERE_RADIUS_M = 0.06


def calibration_sphere(radius_m: float = CALIBRATION_SPHERE_RADIUS_M, centre_m=(0.0, 0.0, 0.0),
                       subdivisions: int = 4):
    """The calibration ball: an icosphere (every vertex on the sphere) of ``radius_m`` metres
    centred at ``centre_m`` (3,), world frame, as a closed trimesh.  With 4 subdivisions and 60 mm
    its facets lie at most 0.03 mm inside the ideal sphere; the calibration measures against the
    mesh itself (the surface the simulation sees)."""
    r = check_positive(radius_m, "radius_m")
    c = check_vector(centre_m, "centre_m", 3)
    if not isinstance(subdivisions, int) or isinstance(subdivisions, bool) or not 1 <= subdivisions <= 6:
        raise ValueError(f"subdivisions must be an integer in [1, 6]; got {subdivisions!r}")
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=r)
    mesh.apply_translation(c)
    return mesh
