"""The estimate of an object resting on a table whose height the robot knows (pure functions).

The arm cannot reach under a resting object, nor below its lowest horizontal wrap (the base block
must clear the table).  Two facts close the estimate: the object stands on the table, and nothing
of it is below the table.  :func:`support_points` extends the lowest layer of contacts straight
down to the table plane (the object's walls are taken to continue vertically below the lowest
touch: exact for prisms, an over-estimate of at most the lowest wrap's height times the wall's
inward slope otherwise); :func:`cut_at_table` removes what an estimate has below the plane, so its
bottom face is the table's.  World frame, z up, metres.
"""
from __future__ import annotations

import numpy as np

from explore3d.geometry.bodies import one_body

__all__ = ["support_points", "cut_at_table"]


def support_points(points, table_z: float, layer_m: float) -> np.ndarray:
    """(k, 3) the points of ``points`` (m, 3) within ``layer_m`` of the lowest one, moved straight
    down onto the plane z = ``table_z`` (empty when there are no points)."""
    P = np.asarray(points, dtype=float).reshape(-1, 3)
    if not len(P):
        return np.zeros((0, 3))
    low = P[P[:, 2] <= P[:, 2].min() + float(layer_m)].copy()
    low[:, 2] = float(table_z)
    return low


def cut_at_table(mesh, table_z: float):
    """``mesh`` (closed trimesh, world frame) without the part below z = ``table_z``, capped with
    the table's face (closed), without the slivers the cut leaves (:func:`explore3d.geometry.bodies.one_body`);
    ``mesh`` itself when nothing of it is below."""
    if float(mesh.bounds[0, 2]) >= float(table_z):
        return mesh
    out = mesh.slice_plane([0.0, 0.0, float(table_z)], [0.0, 0.0, 1.0], cap=True)
    return one_body(out)[0]
