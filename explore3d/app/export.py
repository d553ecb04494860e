"""Writing results: estimate meshes, a URDF that loads the estimate in PyBullet, and point clouds.

Every file goes through :mod:`explore3d.core.io` (atomic: a killed run leaves no half-written file
under its final name).  All coordinates are metres in the frame they are given in (for
explore3d results: the world frame, which is the object's own frame).
"""
from __future__ import annotations

import html
from pathlib import Path

import numpy as np
import trimesh

from explore3d.core.io import atomic_path, atomic_write_bytes, atomic_write_text

#: Mesh formats :func:`write_mesh` writes (OFF is the format GraspIt! reads).
MESH_FORMATS = ("obj", "stl", "ply", "off", "glb")

#: Mesh formats PyBullet's URDF loader reads for collision shapes.
URDF_MESH_FORMATS = ("obj", "stl")

#: PLY vertex properties written by :func:`write_points_ply` besides x, y, z.
POINT_PROPERTIES = ("wrap", "attempt", "link")

#: Float vertex properties of localised contacts (:func:`contact_properties`), SI units: the
#: contact normal (unit, world frame, pointing into the link), the force (N), the position
#: uncertainty along the link (m), the face segment across the link's height the contact lies on
#: (its two ends, world frame, m) and the interval along the link (x in the link frame, m).
CONTACT_PROPERTIES = ("nx", "ny", "nz", "force_n", "uncertainty_m", "seg0_x", "seg0_y", "seg0_z",
                      "seg1_x", "seg1_y", "seg1_z", "along_lo_m", "along_hi_m")


def contact_properties(contacts) -> dict:
    """The :data:`CONTACT_PROPERTIES` of a :class:`~explore3d.feeling.contacts.ContactSet`, (m,) each."""
    c = contacts
    cols = [c.normals[:, 0], c.normals[:, 1], c.normals[:, 2], c.force_n, c.uncertainty_m,
            c.segments[:, 0, 0], c.segments[:, 0, 1], c.segments[:, 0, 2],
            c.segments[:, 1, 0], c.segments[:, 1, 1], c.segments[:, 1, 2],
            c.along_interval_m[:, 0], c.along_interval_m[:, 1]]
    return dict(zip(CONTACT_PROPERTIES, (np.asarray(v, dtype=float) for v in cols)))


def check_format(fmt) -> str:
    """Lower-cased ``fmt`` if it is one of :data:`MESH_FORMATS`, else ValueError naming them."""
    f = str(fmt).lower().lstrip(".")
    if f not in MESH_FORMATS:
        raise ValueError(f"unknown mesh format {fmt!r}; use one of {', '.join(MESH_FORMATS)}")
    return f


def write_mesh(mesh, path, fmt: str | None = None) -> Path:
    """Write ``mesh`` (trimesh.Trimesh, vertices (n, 3) in metres) to ``path`` atomically.

    Args:
        fmt: one of :data:`MESH_FORMATS`; default: the suffix of ``path``.

    Returns the path.  Raises ValueError for an unknown format, OSError if it cannot be written.
    """
    path = Path(path)
    fmt = check_format(fmt if fmt is not None else path.suffix)
    data = mesh.export(file_type=fmt)
    if isinstance(data, str):
        data = data.encode("utf-8")
    return atomic_write_bytes(path, data)


#: Default density of the estimate body in ``estimate.urdf``, kg/m^3 (about that of wood or a
#: hollow plastic part: a stated placeholder; the robot does not sense mass).
DEFAULT_DENSITY_KG_M3 = 500.0


def mass_properties(mesh, density: float = DEFAULT_DENSITY_KG_M3) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass (kg), centre of mass (3,) in the mesh frame (metres) and inertia tensor (3, 3) about
    the centre of mass in the mesh frame's axes (kg m^2) of ``mesh`` (closed trimesh, metres) filled
    with a uniform ``density`` kg/m^3.  Raises ValueError for a bad density or a mesh that is
    not a closed positive volume."""
    rho = float(density)
    if not (np.isfinite(rho) and rho > 0):
        raise ValueError(f"density must be a positive number of kg/m^3; got {density!r}")
    if not (mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0):
        raise ValueError("the estimate mesh must be a closed, outward-wound volume to give mass and inertia; "
                         f"got watertight={mesh.is_watertight}, volume={mesh.volume:.3g} m^3")
    mp = mesh.mass_properties  # density 1: mass = volume, inertia per unit density
    return rho * float(mp["volume"]), np.asarray(mp["center_mass"], dtype=float), rho * np.asarray(mp["inertia"])


def estimate_urdf(mesh_filename: str, mass: float, com, inertia, name: str = "estimate") -> str:
    """URDF text of one rigid link whose visual and collision geometry is ``mesh_filename``
    (a path relative to the URDF's folder, metres, scale 1).  The link's frame is the mesh's
    frame; ``mass`` kg, centre of mass ``com`` (3,) metres in that frame, ``inertia`` (3, 3)
    kg m^2 about the centre of mass (:func:`mass_properties`)."""
    mass = float(mass)
    if not (np.isfinite(mass) and mass > 0):
        raise ValueError(f"mass must be a positive number of kg; got {mass!r}")
    c = np.asarray(com, dtype=float).reshape(3)
    I = np.asarray(inertia, dtype=float).reshape(3, 3)
    fn = html.escape(str(mesh_filename), quote=True)
    return f"""<?xml version="1.0"?>
<robot name="{html.escape(name, quote=True)}">
  <link name="object">
    <inertial>
      <origin xyz="{c[0]:.9g} {c[1]:.9g} {c[2]:.9g}" rpy="0 0 0"/>
      <mass value="{mass:.9g}"/>
      <inertia ixx="{I[0, 0]:.9g}" ixy="{I[0, 1]:.9g}" ixz="{I[0, 2]:.9g}" iyy="{I[1, 1]:.9g}" iyz="{I[1, 2]:.9g}" izz="{I[2, 2]:.9g}"/>
    </inertial>
    <visual>
      <origin xyz="0 0 0" rpy="0 0 0"/>
      <geometry><mesh filename="{fn}" scale="1 1 1"/></geometry>
      <material name="estimate"><color rgba="0.2 0.5 0.9 1"/></material>
    </visual>
    <collision>
      <origin xyz="0 0 0" rpy="0 0 0"/>
      <geometry><mesh filename="{fn}" scale="1 1 1"/></geometry>
    </collision>
  </link>
</robot>
"""


def write_estimate_urdf(mesh_filename, path, mesh, density: float = DEFAULT_DENSITY_KG_M3) -> Path:
    """Write a URDF at ``path`` that loads the exported estimate as one rigid body in PyBullet,
    with the mass, centre of mass and inertia of ``mesh`` filled at ``density`` kg/m^3.

    Args:
        mesh_filename: the exported mesh, a path relative to ``path``'s folder (or absolute).
        path: the URDF to write.
        mesh: the estimate (closed trimesh, metres, the frame of ``mesh_filename``).  When
            ``mesh_filename`` is not OBJ/STL (PyBullet reads only those for collision) an OBJ
            beside it (same stem, ``.obj``) is written from ``mesh`` and referenced instead.
        density: kg/m^3 (default :data:`DEFAULT_DENSITY_KG_M3`).

    Returns the URDF path.
    """
    path = Path(path)
    mass, com, inertia = mass_properties(mesh, density)
    fn = Path(mesh_filename)
    if fn.suffix.lower().lstrip(".") not in URDF_MESH_FORMATS:
        fn = fn.with_suffix(".obj")
        target = fn if fn.is_absolute() else path.parent / fn
        write_mesh(mesh, target, "obj")
    return atomic_write_text(path, estimate_urdf(fn.as_posix(), mass, com, inertia))


def write_points_ply(points, path, wrap=None, attempt=None, link=None, binary: bool = True,
                     extra: dict | None = None) -> Path:
    """Write the hull's input points as a PLY point cloud (atomic).

    Args:
        points: (m, 2) or (m, 3) float, metres; 2D points get z = 0.
        wrap, attempt, link: (m,) int each (default zeros): which wrap, attempt and link gave each point.
        binary: binary little-endian (default) or ASCII PLY.
        extra: more float vertex properties, name -> (m,) (e.g. :func:`contact_properties`).

    The vertex element has float x, y, z, int wrap, attempt, link, then the ``extra`` floats.
    """
    P = np.asarray(points, dtype=float)
    if P.ndim != 2 or P.shape[1] not in (2, 3):
        raise ValueError(f"points must be (m, 2) or (m, 3); got shape {P.shape}")
    if not np.all(np.isfinite(P)):
        raise ValueError("points contain NaN or inf")
    m = len(P)
    if P.shape[1] == 2:
        P = np.column_stack([P, np.zeros(m)])
    cols = {}
    for name, v in zip(POINT_PROPERTIES, (wrap, attempt, link)):
        a = np.zeros(m, dtype=np.int64) if v is None else np.asarray(v)
        if a.shape != (m,):
            raise ValueError(f"{name} must have shape ({m},) like the points; got {a.shape}")
        cols[name] = a.astype(np.int32)
    extra = {} if extra is None else dict(extra)
    for name, v in extra.items():
        a = np.asarray(v, dtype=float)
        if a.shape != (m,) or name in ("x", "y", "z", *POINT_PROPERTIES) or not str(name).isidentifier():
            raise ValueError(f"extra property {name!r} must be a new identifier with shape ({m},) like the points; "
                             f"got shape {a.shape}")
        extra[name] = a
    dtype = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4")] + [(n, "<i4") for n in POINT_PROPERTIES]
                     + [(n, "<f8") for n in extra])
    rec = np.empty(m, dtype=dtype)
    rec["x"], rec["y"], rec["z"] = P[:, 0], P[:, 1], P[:, 2]
    for n in POINT_PROPERTIES:
        rec[n] = cols[n]
    for n, v in extra.items():
        rec[n] = v
    fmt = "binary_little_endian" if binary else "ascii"
    header = (f"ply\nformat {fmt} 1.0\ncomment explore3d hull input points, metres, world frame\n"
              f"element vertex {m}\nproperty float x\nproperty float y\nproperty float z\n"
              + "".join(f"property int {n}\n" for n in POINT_PROPERTIES)
              + "".join(f"property double {n}\n" for n in extra) + "end_header\n")
    if binary:
        body = rec.tobytes()
    else:
        lines = [" ".join([f"{r['x']:.9g} {r['y']:.9g} {r['z']:.9g} {r['wrap']} {r['attempt']} {r['link']}"]
                          + [f"{r[n]:.17g}" for n in extra]) for r in rec]
        body = ("\n".join(lines) + ("\n" if lines else "")).encode("ascii")
    return atomic_write_bytes(path, header.encode("ascii") + body)


def read_points_ply(path, with_properties: bool = False):
    """Read a point file (PLY, or any point/mesh file trimesh loads, or a text XYZ file).

    Returns (n, 3) float64 metres; with ``with_properties`` also a dict of the (n,) vertex
    properties found among :data:`POINT_PROPERTIES` (int) and :data:`CONTACT_PROPERTIES` (float)
    (PLY only; else empty).

    Raises ValueError (missing, unreadable, or no points) naming the problem.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"point file not found: {path}; check the path")
    if path.stat().st_size == 0:
        raise ValueError(f"point file {path} is empty; pass a PLY/XYZ file with points")
    props = {}
    if path.suffix.lower() in (".xyz", ".txt", ".csv"):
        try:
            pts = np.loadtxt(path, delimiter="," if path.suffix.lower() == ".csv" else None, ndmin=2)[:, :3]
        except ValueError as exc:
            raise ValueError(f"cannot read {path} as x y z rows ({exc}); pass a PLY or XYZ file") from None
    else:
        try:
            loaded = trimesh.load(str(path), process=False)
        except Exception as exc:  # trimesh raises many types for unreadable files
            raise ValueError(f"cannot read {path} as a point file ({type(exc).__name__}: {exc}); "
                             "pass a PLY or XYZ file") from None
        if isinstance(loaded, trimesh.Scene):
            geoms = list(loaded.dump()) if len(loaded.geometry) else []
            if not geoms:
                raise ValueError(f"{path} contains no points; pass a PLY or XYZ file with points")
            loaded = geoms[0] if len(geoms) == 1 else trimesh.util.concatenate(geoms)
        pts = np.asarray(getattr(loaded, "vertices", np.empty((0, 3))), dtype=float)
        attrs = getattr(loaded, "metadata", {}).get("_ply_raw", {}).get("vertex", {}).get("data")
        # binary PLY: a structured array; ASCII PLY: a dict of (n, 1) arrays
        names = attrs.keys() if isinstance(attrs, dict) else (getattr(getattr(attrs, "dtype", None), "names", None) or ())
        kinds = [(n, np.int64) for n in POINT_PROPERTIES] + [(n, np.float64) for n in CONTACT_PROPERTIES]
        for n, t in kinds:
            if n in names:
                props[n] = np.asarray(attrs[n], dtype=t).reshape(-1)
        if not props and hasattr(loaded, "vertex_attributes"):
            for n, t in kinds:
                if n in loaded.vertex_attributes:
                    props[n] = np.asarray(loaded.vertex_attributes[n], dtype=t).reshape(-1)
    if pts.ndim != 2 or pts.shape[0] == 0 or pts.shape[1] != 3:
        raise ValueError(f"{path} contains no 3D points; pass a PLY or XYZ file with points")
    if not np.all(np.isfinite(pts)):
        raise ValueError(f"{path} contains NaN or inf coordinates")
    return (pts, props) if with_properties else pts


def points_2d_if_planar(points, tol: float = 1e-12) -> np.ndarray:
    """(n, 2) if every z of the (n, 3) ``points`` is 0 (a planar exploration), else the points."""
    P = np.asarray(points, dtype=float)
    if P.shape[1] == 3 and np.all(np.abs(P[:, 2]) <= tol):
        return P[:, :2]
    return P
