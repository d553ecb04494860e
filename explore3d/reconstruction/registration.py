"""Where a pushed object went: rigid registration of new contacts to an earlier estimate (pure
numpy and trimesh).

An object resting on a table can only slide and turn on it: its motion is a rotation about the
vertical and a horizontal translation (three numbers; the robot is told the table's height, so it
knows that much).  When the robot's own data say the object moved
(:mod:`explore3d.strategy.motion`), the contacts gathered since lie on the moved object;
:func:`register_on_table` finds the planar motion that puts them back on the estimate built from
the contacts before (point-to-plane Gauss-Newton on the estimate's nearest surface points), so
the later contacts can be carried back into the frame of the earlier ones and hulled together.

A planar motion is observable from the contacts only when their surface normals span it (contacts
on one flat face fix one direction only): :attr:`Registration.observable` says so, from the
singular values of the problem's Jacobian.

World frame, z up, metres, radians.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Registration", "planar_transform", "register_on_table"]

#: a direction of the planar motion counts as observed when the Jacobian's singular value along it
#: is at least this fraction of the square root of the number of points (unit normals: a face seen
#: by every point gives 1 along its normal; angles are scaled by the points' spread first)
MIN_OBSERVABILITY = 0.1


@dataclass(frozen=True)
class Registration:
    """A planar rigid motion found by :func:`register_on_table`.

    Attributes:
        T: (4, 4) the transform that maps the registered points onto the estimate (world frame):
            a rotation by ``yaw_rad`` about the vertical through ``pivot`` and a translation.
        translation_m: (2,) its horizontal translation, x and y, m (after the rotation about the pivot).
        yaw_rad: its rotation about the vertical, rad.
        pivot: (3,) the point the rotation is about (the points' centroid), m.
        rms_before_m, rms_m: RMS distance of the points from the estimate's surface before and after, m.
        iterations: Gauss-Newton iterations taken.
        observable: the points' normals span the planar motion (see :data:`MIN_OBSERVABILITY`);
            False: the motion is only partly fixed and ``T`` should not be trusted.
    """

    T: np.ndarray
    translation_m: np.ndarray
    yaw_rad: float
    pivot: np.ndarray
    rms_before_m: float
    rms_m: float
    iterations: int
    observable: bool


def planar_transform(dx: float, dy: float, yaw: float, pivot=(0.0, 0.0, 0.0)) -> np.ndarray:
    """(4, 4) a rotation by ``yaw`` rad about the vertical through ``pivot`` (3,), m, then a
    translation by (``dx``, ``dy``, 0), m."""
    c, s = math.cos(yaw), math.sin(yaw)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    p = np.asarray(pivot, dtype=float).reshape(3)
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = p - R @ p + np.array([dx, dy, 0.0])
    return T


def _nearest(mesh, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    closest, _, tri = mesh.nearest.on_surface(P)
    return np.asarray(closest, float), np.asarray(mesh.face_normals[tri], float)


def register_on_table(points, estimate, max_iterations: int = 50, tol_m: float = 1.0e-7,
                      huber_m: float = 1.0e-3) -> Registration:
    """The planar motion (yaw about the vertical, horizontal translation) that best puts ``points``
    (m, 3), world frame, m, on the surface of ``estimate`` (a closed trimesh, world frame):
    least squares of the points' distances along the surface normal at their nearest surface
    points (point-to-plane ICP restricted to the table's three degrees of freedom), with Huber
    weights beyond ``huber_m`` (m): points where the estimate is wrong (an edge it cut, a face it
    never saw) pull less than points where it is right.

    Raises:
        ValueError: fewer than 3 points, or not finite.
    """
    P = np.asarray(points, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3 or len(P) < 3 or not np.isfinite(P).all():
        raise ValueError(f"register_on_table needs at least 3 finite points (m, 3), m; got shape {P.shape}")
    pivot = P.mean(axis=0)
    spread = max(float(np.sqrt(((P[:, :2] - pivot[:2]) ** 2).sum(axis=1).mean())), 1.0e-6)
    x = np.zeros(3)  # dx, dy, yaw
    rms0 = None
    rms = float("nan")
    it = 0
    J = np.zeros((len(P), 3))
    for it in range(1, max_iterations + 1):
        T = planar_transform(x[0], x[1], x[2], pivot)
        Q = P @ T[:3, :3].T + T[:3, 3]
        C, N = _nearest(estimate, Q)
        r = np.einsum("ij,ij->i", N, Q - C)
        rms = float(np.sqrt(np.mean(r * r)))
        if rms0 is None:
            rms0 = rms
        lever = Q - (pivot + np.array([x[0], x[1], 0.0]))
        J = np.stack([N[:, 0], N[:, 1], N[:, 1] * lever[:, 0] - N[:, 0] * lever[:, 1]], axis=1)
        Js = J * np.array([1.0, 1.0, 1.0 / spread])
        w = np.sqrt(np.minimum(1.0, huber_m / np.maximum(np.abs(r), 1e-300)))  # Huber weights (IRLS)
        step, *_ = np.linalg.lstsq(Js * w[:, None], -r * w, rcond=1e-6)
        step = step * np.array([1.0, 1.0, 1.0 / spread])
        x = x + step
        if np.abs(step[:2]).max() < tol_m and abs(step[2]) * spread < tol_m:
            break
    T = planar_transform(x[0], x[1], x[2], pivot)
    Q = P @ T[:3, :3].T + T[:3, 3]
    C, N = _nearest(estimate, Q)
    rms = float(np.sqrt(np.mean(np.einsum("ij,ij->i", N, Q - C) ** 2)))
    sv = np.linalg.svd(J * np.array([1.0, 1.0, 1.0 / spread]), compute_uv=False)
    observable = bool(sv.min() >= MIN_OBSERVABILITY * math.sqrt(len(P)))
    return Registration(T=T, translation_m=x[:2].copy(), yaw_rad=float(x[2]), pivot=pivot, rms_before_m=float(rms0),
                        rms_m=rms, iterations=it, observable=observable)
