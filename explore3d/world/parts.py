"""The convex parts a dynamic object collides as in PyBullet (its convex hull, or V-HACD's
decomposition of a non-convex mesh), as OBJ text with one group per part.  Units: metres."""
from __future__ import annotations

import functools
import os
import tempfile

import numpy as np
import trimesh

from explore3d.core.interrupt import deferred_signals
from explore3d.core.quiet import quiet_c_output


def _is_convex(mesh) -> bool:
    return float(mesh.volume) >= (1.0 - 1e-6) * float(mesh.convex_hull.volume)


def _parse_obj_parts(text: str) -> list[tuple[np.ndarray, np.ndarray]]:
    """The ``o`` groups of an OBJ file as (vertices (v, 3), faces (f, 3)) each (faces re-indexed)."""
    verts, groups = [], []
    for line in text.splitlines():
        t = line.split()
        if not t:
            continue
        if t[0] == "v":
            verts.append([float(x) for x in t[1:4]])
        elif t[0] == "o" or (t[0] == "f" and not groups):
            groups.append([])
            if t[0] == "f":
                groups[-1].append([int(x.split("/")[0]) - 1 for x in t[1:4]])
        elif t[0] == "f":
            groups[-1].append([int(x.split("/")[0]) - 1 for x in t[1:4]])
    V = np.asarray(verts, dtype=float)
    out = []
    for g in groups:
        if not g:
            continue
        F = np.asarray(g, dtype=np.int64)
        used, inv = np.unique(F, return_inverse=True)
        out.append((V[used], inv.reshape(F.shape)))
    return out


def parts_obj_text(parts) -> str:
    """OBJ text with one ``o`` group per convex part ((vertices (v, 3), faces (f, 3)) each)."""
    lines, base = [], 1
    for i, (V, F) in enumerate(parts):
        lines.append(f"o part{i}")
        lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in np.asarray(V, float)]
        lines += [f"f {a + base} {b + base} {c + base}" for a, b, c in np.asarray(F, int)]
        base += len(V)
    return "\n".join(lines) + "\n"


@functools.lru_cache(maxsize=16)
def _vhacd(obj_text: str) -> str:
    with tempfile.TemporaryDirectory(prefix="explore3d_vhacd_") as d, quiet_c_output():
        import pybullet  # kept out of explore3d --help's start-up
        from pybullet_utils import bullet_client

        with deferred_signals():  # a Ctrl-C inside would leave a half-made client whose __del__ complains
            client = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
        try:
            src, dst, log = (os.path.join(d, n) for n in ("in.obj", "out.obj", "log.txt"))
            with open(src, "w") as fh:
                fh.write(obj_text)
            client.vhacd(src, dst, log)
            with open(dst) as fh:
                return fh.read()
        finally:
            client.disconnect()


def convex_parts(mesh) -> list[tuple[np.ndarray, np.ndarray]]:
    """The convex parts a dynamic ``mesh`` (closed trimesh, metres) collides as: its convex hull
    when it is convex (volume within 1e-6 of the hull's), else PyBullet's V-HACD decomposition
    (default parameters; deterministic).  Returns [(vertices (v, 3), faces (f, 3))], mesh frame."""
    if _is_convex(mesh):
        h = mesh.convex_hull
        return [(np.asarray(h.vertices, float), np.asarray(h.faces, np.int64))]
    return _parse_obj_parts(_vhacd(parts_obj_text([(mesh.vertices, mesh.faces)])))


def _union(parts):
    meshes = [trimesh.Trimesh(V, F, process=True).convex_hull for V, F in parts]
    if len(meshes) == 1:
        return meshes[0]
    return trimesh.boolean.union(meshes, engine="manifold")
