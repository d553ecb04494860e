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

import dataclasses

import numpy as np

from explore3d.arm.kinematics import link_surface_points
from explore3d.arm.spec import ArmSpec
from explore3d.reconstruction.freespace import is_free
from explore3d.reconstruction.hull_input import reconstruct_points
from explore3d.reconstruction.registration import register_on_table

__all__ = ["DEFAULT_DEPTH_M", "DEFAULT_MIN_SEGMENTS", "contact_segments", "deep_free", "moved_after", "wrap_epochs",
           "carry_back", "motion_trust"]

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


#: an epoch's points are carried back only when the epoch before the first motion has at least this
#: many points to register them to (fewer give no estimate to register against)
MIN_REFERENCE_POINTS = 30
#: a registration counts only when it brings the epoch's RMS distance from the estimate down to at
#: most this fraction of what it was (measured on the table cube's link points, 5-15 mm off the
#: surface: a 7-degree turn that moved the RMS from 18.4 to 18.0 mm was no registration)
REGISTERED_RMS_FRACTION = 0.5
#: an epoch whose motion is not observable (:attr:`~explore3d.reconstruction.registration.Registration.observable`)
#: is kept as it is when its points already lie this close (RMS, m) to the estimate, else dropped
KEEP_UNREGISTERED_RMS_M = 1.0e-3


def wrap_epochs(moved) -> np.ndarray:
    """(n_wraps,) int: the epoch of each wrap: 0 up to and including the first wrap flagged in
    ``moved`` (n_wraps,) bool, then 1 up to the next, ... (a flagged wrap ends its epoch: the object
    moved while it ran, so its contacts mix two poses)."""
    moved = np.asarray(moved, dtype=bool)
    return np.concatenate([[0], np.cumsum(moved)[:-1]]).astype(int) if len(moved) else np.zeros(0, int)


def carry_back(ex, centre, radius: float, a: float | None = None):
    """An :class:`~explore3d.strategy.explore.Exploration` of a resting object that moved
    (:attr:`~explore3d.strategy.explore.Exploration.moved`), with the points and swept space of every
    epoch after a motion (:func:`wrap_epochs`) carried back onto the estimate of the ones before:
    the planar motion (yaw and horizontal slide on the table) that puts an epoch's points on the
    inverse hull of the points so far (:func:`explore3d.reconstruction.registration.register_on_table`) is
    undone on its points and swept areas.  The flagged wraps' own points and swept space are
    dropped.  Returns ``ex`` unchanged without a table, without a flag, or when the first epoch has
    fewer than :data:`MIN_REFERENCE_POINTS` points; else a copy whose ``registrations`` holds one
    dict per later epoch (its wraps, points, translation m, yaw deg, RMS before and after m,
    observable, and what was done: ``"registered"``, ``"kept"`` or ``"dropped"``; an epoch is kept
    as it is, with a ``reason``, when the points before it give no estimate to register to)."""
    if ex.table_z is None or ex.moved is None or not np.any(ex.moved):
        return ex
    flagged = np.asarray(ex.moved, dtype=bool)
    epoch = wrap_epochs(flagged)
    pw = np.asarray(ex.point_wrap, int)
    keep_pt = ~flagged[pw]
    P = np.asarray(ex.points, float).copy()
    ref = keep_pt & (epoch[pw] == 0)
    if int(ref.sum()) < MIN_REFERENCE_POINTS:
        return ex
    per_wrap = [len(w) for w in ex.attempts]
    swept = list(ex.swept)
    carry_swept = sum(per_wrap) == len(swept)
    # without a swept area per attempt the swept space cannot be told apart by wrap: carve with none of it
    sw_wrap = np.repeat(np.arange(ex.n_wraps), per_wrap) if carry_swept else np.zeros(len(swept), int)
    keep_sw = ~flagged[sw_wrap] if carry_swept else np.zeros(len(swept), bool)
    pool = ref.copy()
    kw = {} if a is None else {"a": a}
    out = []
    for e in range(1, int(epoch.max()) + 1):
        sel = keep_pt & (epoch[pw] == e)
        wraps = sorted({int(w) for w in np.nonzero(epoch == e)[0]})
        rec = {"epoch": e, "wraps": wraps, "points": int(sel.sum())}
        if sel.sum() < 3:
            rec["action"] = "dropped"
            keep_pt &= ~sel
            out.append(rec)
            continue
        try:
            est = reconstruct_points(P[pool], pw[pool], centre, radius, **kw).mesh
        except ValueError as exc:  # the points so far do not surround the centre: nothing to register to
            rec.update(action="kept", reason=f"no estimate to register to: {str(exc).split('; ')[0]}")
            pool |= sel
            out.append(rec)
            continue
        reg = register_on_table(P[sel], est)
        rec.update(translation_m=[float(v) for v in reg.translation_m], yaw_deg=float(np.degrees(reg.yaw_rad)),
                   rms_before_m=reg.rms_before_m, rms_m=reg.rms_m, observable=reg.observable)
        if reg.observable and reg.rms_m <= REGISTERED_RMS_FRACTION * reg.rms_before_m:
            T = reg.T
            P[sel] = P[sel] @ T[:3, :3].T + T[:3, 3]
            for i in np.nonzero((epoch[sw_wrap] == e) & keep_sw)[0]:
                swept[i] = dataclasses.replace(swept[i], T_world_base=T @ np.asarray(swept[i].T_world_base))
            rec["action"] = "registered"
            pool |= sel
        elif reg.rms_before_m <= KEEP_UNREGISTERED_RMS_M:
            rec["action"] = "kept"
            pool |= sel
        else:
            rec["action"] = "dropped"
            keep_pt &= ~sel
            keep_sw &= epoch[sw_wrap] != e
        out.append(rec)
    return dataclasses.replace(ex, points=P[keep_pt], point_wrap=pw[keep_pt],
                               point_attempt=np.asarray(ex.point_attempt)[keep_pt],
                               point_link=np.asarray(ex.point_link)[keep_pt],
                               swept=tuple(s for s, k in zip(swept, keep_sw) if k), registrations=tuple(out))


def motion_trust(moved, point_wrap, registrations=()) -> dict:
    """How far an estimate can be trusted against the object's own motion, by the robot's readings
    alone: the wraps flagged in ``moved`` (n_wraps,) bool (:func:`moved_after`), the points
    ``point_wrap`` (p,) int of each epoch (:func:`wrap_epochs`) and what :func:`carry_back` did with
    them (``registrations``, its dicts; () when the points were not carried back).

    Returns a JSON-ready dict: ``wraps_flagged`` (list of int), ``points_by_epoch`` (epoch 0 first;
    a flagged wrap's own points are counted in no epoch: they mix two poses),
    ``points_flagged_wraps``, ``consistent_fraction`` (the points that lie on one pose of the
    object: epoch 0's and every registered or kept epoch's, over all points), ``resolution_m``
    (:data:`DEFAULT_DEPTH_M`: a motion that leaves every contact segment within it of the swept
    space's edge is not noticed) and ``verdict``: ``"no motion noticed"``, ``"carried back"`` (every
    later epoch registered or kept) or ``"mixed poses"`` (the estimate mixes the object's poses;
    only ``consistent_fraction`` of its points agree), with ``note``, one sentence for a user."""
    moved = np.asarray(moved, dtype=bool)
    pw = np.asarray(point_wrap, dtype=int)
    epoch = wrap_epochs(moved)
    n_epochs = int(epoch.max()) + 1 if len(epoch) else 1
    flagged_pt = moved[pw] if len(moved) else np.zeros(len(pw), bool)
    by_epoch = [int(((epoch[pw] == e) & ~flagged_pt).sum()) if len(moved) else int(len(pw)) for e in range(n_epochs)]
    agreed = {0} | {int(r["epoch"]) for r in registrations if r.get("action") in ("registered", "kept")}
    total = int(len(pw))
    consistent = sum(n for e, n in enumerate(by_epoch) if e in agreed)
    flagged = np.nonzero(moved)[0].tolist()
    out = {"wraps_flagged": flagged, "points_by_epoch": by_epoch, "points_flagged_wraps": int(flagged_pt.sum()),
           "consistent_fraction": consistent / total if total else 1.0, "resolution_m": DEFAULT_DEPTH_M}
    if not flagged:
        out.update(verdict="no motion noticed",
                   note=f"the contacts and swept space agree: no motion of more than about "
                        f"{1e3 * DEFAULT_DEPTH_M:g} mm was noticed")
    elif registrations and all(e in agreed for e in range(1, n_epochs) if by_epoch[e]):
        out.update(verdict="carried back",
                   note=f"the object moved during wraps {flagged}; the points after each motion were carried back "
                        "onto the estimate before it")
    else:
        out.update(verdict="mixed poses",
                   note=f"the object moved during wraps {flagged}; the estimate mixes its poses: "
                        f"{100 * out['consistent_fraction']:.0f}% of the points lie on its first pose "
                        "(SceneConfig.register_moved carries the later ones back)")
    return out
