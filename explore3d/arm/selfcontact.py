"""Self-contact of the chain, told from its own kinematics (pure numpy).

A curling chain can touch itself: a link folding back onto the one two places before it, the
distal chain coming round onto the proximal links or the base block after a full turn.  The
simulation collides the arm with itself (:attr:`explore3d.core.settings.SimConfig.self_collision`), so such a
touch loads the joints like an object does.  The robot cannot see it, but it knows where its
links are: this module computes, from the joint angles and the arm's model alone, how far apart
its bodies are.

Geometry.  The bodies are the base block and the n link boxes (:mod:`explore3d.arm.spec`).  All joint
axes are the base z axis and every body is centred on the base's z = 0 plane, so every box spans a
z range around 0 that overlaps every other's, and the distance between two boxes is exactly the
distance between their rectangles in the arm's plane.  That is computed exactly: for two
rectangles apart, the smallest corner-to-edge distance (two convex polygons apart have a closest
pair with a corner of one of them); overlapping, minus the penetration depth: the least translation
that separates them, along the best of the eight edge normals (separating-axis test; for convex
polygons in the plane that is the least) or along z (the sum of the two half heights).

PyBullet's boxes differ from the model's at their edges: its URDF importer gives every link box a
collision margin of 1 mm (``changeDynamics(collisionMargin=...)`` does not reach it), which rounds
the box's edges with that radius, so the simulated distance between two links is the model's plus
0 to 2 (sqrt(2) - 1) x 1 mm (edge against edge); the model never reads two bodies farther apart
than the simulation (tests/test_selfcontact.py).

Bodies are numbered like PyBullet's links of the arm: -1 the base block, i = 0..n-1 link i.  Two
bodies are *adjacent* when a joint connects them (the base and link 0, link i and link i + 1):
their boxes meet at the joint and overlap on the inner side of a bent joint at any angle, so
adjacent pairs are never a self-contact (the simulation excludes them too).

Lengths in metres, angles in radians.
"""
from __future__ import annotations

import functools

import numpy as np

from explore3d.arm.kinematics import link_frames_planar, link_transforms
from explore3d.arm.spec import BASE_GAP_M, ArmSpec

__all__ = ["BASE", "body_rectangles", "rectangle_distances", "self_distances", "self_contact_pairs",
           "point_body_distances", "near_other_body", "SELF_CONTACT_TOLERANCE_M"]

#: The body index of the base block (links are 0..n-1).
BASE = -1

#: How close, metres, two non-adjacent bodies may be by the model at the sensed angles and still be
#: counted as touching each other (the default of ``ControlConfig.self_contact_tolerance`` and of
#: the localisation's test, :func:`explore3d.feeling.contacts.on_the_arm`).  Measured on 12 wraps of the
#: 80 mm cube (default 3D setting and sensing): at the detections where PyBullet reported an
#: arm-arm contact (56 and 43 with two versions of the controller), the model put the touching pair
#: at most 0.37 mm apart (the model's sharp boxes are never farther apart than PyBullet's rounded
#: ones; the sensed angles are one step late and quantised to 1.5 mrad).
SELF_CONTACT_TOLERANCE_M = 1.0e-3


def _base_rectangle(spec: ArmSpec) -> np.ndarray:
    """(4, 2) the base block's corners in the base plane, counterclockwise, metres."""
    b = spec.base_size
    x0, x1 = -BASE_GAP_M - b, -BASE_GAP_M
    return np.array([[x0, -b / 2], [x1, -b / 2], [x1, b / 2], [x0, b / 2]])


def body_rectangles(spec: ArmSpec, q) -> np.ndarray:
    """(..., n + 1, 4, 2) every body's outline in the base x-y plane, metres, corners
    counterclockwise: index 0 the base block, index i + 1 link i, at joint angles ``q`` (..., n), rad."""
    origins, headings = link_frames_planar(spec, q)
    L, w = spec.link_length, spec.link_width / 2.0
    local = np.array([[0.0, -w], [L, -w], [L, w], [0.0, w]])  # link frame, counterclockwise
    c, s = np.cos(headings)[..., None], np.sin(headings)[..., None]
    x = origins[..., None, 0] + c * local[:, 0] - s * local[:, 1]
    y = origins[..., None, 1] + s * local[:, 0] + c * local[:, 1]
    links = np.stack([x, y], axis=-1)  # (..., n, 4, 2)
    base = np.broadcast_to(_base_rectangle(spec), links.shape[:-3] + (1, 4, 2))
    return np.concatenate([base, links], axis=-3)


def _point_segment_distance(P, A, B) -> np.ndarray:
    """Distance between points P (..., 2) and segments A-B (..., 2), broadcast."""
    AB = B - A
    t = np.clip(np.sum((P - A) * AB, axis=-1) / np.maximum(np.sum(AB * AB, axis=-1), 1e-300), 0.0, 1.0)
    return np.linalg.norm(P - (A + t[..., None] * AB), axis=-1)


def rectangle_distances(R1, R2) -> np.ndarray:
    """Signed distance, metres, between convex quadrilaterals ``R1`` and ``R2`` (..., 4, 2), corners
    counterclockwise, broadcast: the exact distance when they are apart, minus the penetration depth
    (the least translation along an edge normal that separates them) when they overlap."""
    R1, R2 = np.broadcast_arrays(np.asarray(R1, dtype=np.float64), np.asarray(R2, dtype=np.float64))

    def separation(A, B):  # largest gap of B beyond an edge of A, along that edge's outward normal
        E = np.roll(A, -1, axis=-2) - A  # (..., 4, 2) edges
        N = np.stack([E[..., 1], -E[..., 0]], axis=-1) / np.linalg.norm(E, axis=-1, keepdims=True)  # outward (ccw)
        gaps = np.einsum("...ek,...vk->...ev", N, B) - np.sum(N * A, axis=-1)[..., None]  # (..., 4 edges, 4 corners)
        return gaps.min(axis=-1).max(axis=-1)

    sep = np.maximum(separation(R1, R2), separation(R2, R1))

    def corner_edge(A, B):  # smallest distance of A's corners to B's edges
        P = A[..., :, None, :]
        return _point_segment_distance(P, B[..., None, :, :], np.roll(B, -1, axis=-2)[..., None, :, :]).min(axis=(-1, -2))

    apart = np.minimum(corner_edge(R1, R2), corner_edge(R2, R1))
    return np.where(sep > 0, apart, sep)


def _half_heights(spec: ArmSpec) -> np.ndarray:
    """(n + 1,) half extent along z of each body (base block first), metres."""
    half = np.full(spec.n_links + 1, spec.link_height / 2)
    half[0] = spec.base_size / 2
    return half


def _pair_distances(spec: ArmSpec, R: np.ndarray, ia, ib) -> np.ndarray:
    """Signed distance of the body pairs (ia, ib) (indices into ``R`` (..., n + 1, 4, 2)), metres:
    the in-plane distance; overlapping boxes also separate along z, by the two half heights."""
    half = _half_heights(spec)
    return np.maximum(rectangle_distances(R[..., ia, :, :], R[..., ib, :, :]), -(half[ia] + half[ib]))


def self_distances(spec: ArmSpec, q) -> np.ndarray:
    """(..., n + 1, n + 1) signed distance between every two bodies of the arm at joint angles ``q``
    (..., n), rad, metres (negative: overlapping, by the penetration depth; see the module
    docstring).  Row and column 0 are the base block, i + 1 link i (``BASE + 1`` = 0).  A body with
    itself and adjacent bodies (joined by a joint) read +inf."""
    R = body_rectangles(spec, q)
    m = R.shape[-3]
    ia, ib = np.triu_indices(m, k=2)  # non-adjacent pairs: bodies b-1, b, b+1 are a chain
    d = _pair_distances(spec, R, ia, ib)
    out = np.full(R.shape[:-3] + (m, m), np.inf)
    out[..., ia, ib] = d
    out[..., ib, ia] = d
    return out


@functools.lru_cache(maxsize=8)
def _non_adjacent_pairs(m: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.triu_indices(m, k=2)`` as read-only arrays, once per body count (the band's
    calibration asks at every step)."""
    ia, ib = np.triu_indices(m, k=2)
    ia.flags.writeable = ib.flags.writeable = False
    return ia, ib


def self_contact_pairs(spec: ArmSpec, q, tolerance_m: float = SELF_CONTACT_TOLERANCE_M,
                       moving_from: int | None = None) -> list[tuple[int, int]]:
    """The pairs of non-adjacent bodies within ``tolerance_m`` metres of each other at the joint
    angles ``q`` (n,), rad, as (a, b) body indices, a < b (-1 the base block), sorted.

    ``moving_from``: only pairs across joint ``moving_from`` (``a < moving_from <= b``): the links it
    carries against the base and the links before it, the pairs whose distance the joint's sweep
    changes (None: every pair).  Pairs whose bounding circles are farther apart than the tolerance
    are dismissed before the exact distance (:func:`self_distances`) is computed."""
    if not (isinstance(tolerance_m, (int, float, np.floating)) and np.isfinite(tolerance_m) and tolerance_m >= 0):
        raise ValueError(f"tolerance_m must be a finite number >= 0, metres; got {tolerance_m!r}")
    q = np.asarray(q, dtype=np.float64)
    if q.shape != (spec.n_links,):
        raise ValueError(f"q must have shape ({spec.n_links},), rad; got {q.shape}")
    R = body_rectangles(spec, q)
    ia, ib = _non_adjacent_pairs(R.shape[0])
    if moving_from is not None:
        keep = (ia - 1 < moving_from) & (moving_from <= ib - 1)
        ia, ib = ia[keep], ib[keep]
    centre = R.mean(axis=1)
    radius = np.linalg.norm(R - centre[:, None, :], axis=-1).max(axis=1)
    near = np.linalg.norm(centre[ia] - centre[ib], axis=-1) - radius[ia] - radius[ib] <= tolerance_m
    ia, ib = ia[near], ib[near]
    if not len(ia):
        return []
    touch = _pair_distances(spec, R, ia, ib) <= tolerance_m
    return [(int(a) - 1, int(b) - 1) for a, b in zip(ia[touch], ib[touch])]


def point_body_distances(spec: ArmSpec, q, points, T_world_base=None) -> np.ndarray:
    """(m, n + 1) distance, metres, from each of ``points`` (m, 3), world frame, to each body's box
    at joint angles ``q`` (n,), rad (column 0 the base block, i + 1 link i; 0 inside a box).
    ``T_world_base`` (4, 4): the base pose (None: the identity)."""
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    T = link_transforms(spec, q, T_world_base)  # (n, 4, 4)
    Tb = np.eye(4) if T_world_base is None else np.asarray(T_world_base, dtype=np.float64)
    # every body as (frame, lower corner, upper corner) in its frame
    frames = np.concatenate([Tb[None], T], axis=0)
    b, H = spec.base_size, spec.link_height
    lo = np.tile([0.0, -spec.link_width / 2, -H / 2], (spec.n_links + 1, 1))
    hi = np.tile([spec.link_length, spec.link_width / 2, H / 2], (spec.n_links + 1, 1))
    lo[0], hi[0] = [-BASE_GAP_M - b, -b / 2, -b / 2], [-BASE_GAP_M, b / 2, b / 2]
    local = np.einsum("bji,mbj->mbi", frames[:, :3, :3], P[:, None, :] - frames[None, :, :3, 3])  # R^T (p - o)
    return np.linalg.norm(local - np.clip(local, lo, hi), axis=-1)


def near_other_body(spec: ArmSpec, q, link, points, T_world_base=None,
                    tolerance_m: float = SELF_CONTACT_TOLERANCE_M) -> np.ndarray:
    """(m,) bool: each of ``points`` (m, 3), world frame, located on ``link`` (m,) int, lies within
    ``tolerance_m`` metres of a body of the arm other than that link and the two adjacent to it (at
    joint angles ``q`` (n,), rad, base pose ``T_world_base``): a contact there is the arm touching
    itself."""
    link = np.asarray(link, dtype=int).reshape(-1)
    D = point_body_distances(spec, q, points, T_world_base)
    if D.shape[0] != link.shape[0]:
        raise ValueError(f"need one link per point; got {link.shape[0]} links for {D.shape[0]} points")
    if ((link < 0) | (link >= spec.n_links)).any():
        raise ValueError(f"links must be in [0, {spec.n_links - 1}]; got {link.tolist()}")
    body = link + 1  # column of the link itself
    cols = np.arange(D.shape[1])[None, :]
    own = np.abs(cols - body[:, None]) <= 1  # the link and its neighbours (the base is link 0's)
    return (np.where(own, np.inf, D) <= tolerance_m).any(axis=1)
