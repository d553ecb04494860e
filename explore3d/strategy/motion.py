"""Noticing that the object moved, from the robot's own data alone (pure numpy).

A resting object can be pushed.  The robot never sees it, but what it knows contradicts itself when
it moves.  Every detected contact lies somewhere on the *contact segment*: the inner faces of the
links the swept joint carried, at mid-height, at the settled reading's angles (the arm's model and
the known base pose; no torque localisation needed), cut to the rough bound the object is known
to lie in.  If a later wrap's links sweep through the whole of an earlier contact's segment, the
object is no longer anywhere it was touched: it went away.  If a wrap's contact segment lies
wholly in space earlier wraps swept through, the object came to where there was nothing.
:func:`moved_after` counts both for one wrap against the wraps before it.  A point counts as
swept when it lies ``depth_m`` inside the swept region in every in-plane direction
(:func:`deep_free`), so the arm's contact margin and encoder resolution do not count.

Inputs are the exploration's own: the attempts' settled readings
(:class:`~explore3d.strategy.encircle.Moment`) and :class:`~explore3d.reconstruction.freespace.SweptArea` (from the
measured joint angles).  Metres.
"""
from __future__ import annotations

import numpy as np

from explore3d.arm.kinematics import link_surface_points
from explore3d.arm.spec import ArmSpec
from explore3d.reconstruction.freespace import is_free

__all__ = ["DEFAULT_DEPTH_M", "DEFAULT_MIN_SEGMENTS", "contact_segments", "deep_free", "moved_after"]

#: a point counts as swept when it lies this far inside swept space in every in-plane direction, m
#: (the links' 1 mm contact margin, the 1 mm pixels and 0.5 mm margin of the swept areas, and
#: about 0.5 mm of encoder resolution at the arm's reach)
DEFAULT_DEPTH_M = 0.003
#: a wrap is flagged when at least this many contact segments contradict the other wraps: a false
#: detection leaves a segment where nothing was touched, which a later sweep crosses (measured: a
#: 1.3 kg cube that did not move, 2 false detections in 54, gave 2 contradicting segments; 6-19 g
#: cubes pushed 20-100 mm gave 2-11 per wrap)
DEFAULT_MIN_SEGMENTS = 3
#: spacing of the points along a contact segment, m
SEGMENT_STEP_M = 0.002


def contact_segments(spec: ArmSpec, attempts, centre, radius: float, step_m: float = SEGMENT_STEP_M) -> list:
    """Per detected contact of ``attempts`` (one wrap's), its contact segment: (k, 3) points, world
    frame, on the inner faces at mid-height of the links the swept joint carried, at the settled
    reading, within ``radius`` of the rough ``centre`` (3,); contacts with fewer than 3 such
    points are left out."""
    n_along = max(2, int(round(spec.link_length / step_m)))
    c = np.asarray(centre, dtype=float)
    out = []
    for a in attempts:
        for m in a.moments:
            P = link_surface_points(spec, m.reading.q, a.T_world_base, n_along, 1, ("inner",))[m.joint:]
            P = P.reshape(-1, 3)
            P = P[np.linalg.norm(P - c, axis=1) <= radius]
            if len(P) >= 3:
                out.append(P)
    return out


def deep_free(areas, points, depth_m: float = DEFAULT_DEPTH_M) -> np.ndarray:
    """(m,) bool: which world points (m, 3) lie in the free space of one of ``areas`` together with
    the eight points ``depth_m`` away from them in that area's plane (axes and diagonals)."""
    P = np.asarray(points, dtype=float).reshape(-1, 3)
    out = np.zeros(len(P), dtype=bool)
    if not len(P):
        return out
    dirs = np.array([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [1, -1], [-1, 1], [-1, -1]], float)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    for a in areas:
        R = np.asarray(a.T_world_base, float)[:3, :3]
        ok = is_free([a], P)
        for d in dirs:
            if not ok.any():
                break
            ok &= is_free([a], P + depth_m * (d[0] * R[:, 0] + d[1] * R[:, 1]))
        out |= ok
    return out


def moved_after(segments, swept, w: int, depth_m: float = DEFAULT_DEPTH_M) -> int:
    """How many contact segments contradict wrap ``w`` and the wraps before it: the earlier wraps'
    segments wholly inside wrap ``w``'s swept space, plus wrap ``w``'s segments wholly inside the
    earlier wraps' swept space.

    Args:
        segments: per wrap, its contact segments (:func:`contact_segments`).
        swept: per wrap, its swept areas (a list of :class:`~explore3d.reconstruction.freespace.SweptArea`).
    """
    away = sum(bool(deep_free(swept[w], s, depth_m).all()) for segs in segments[:w] for s in segs) if swept[w] else 0
    past = [a for s in swept[:w] for a in s]
    came = sum(bool(deep_free(past, s, depth_m).all()) for s in segments[w]) if past else 0
    return int(away + came)
