"""Forward kinematics of the planar chain and the surface points of its links (pure numpy).

Frames follow :mod:`explore3d.arm.spec`: ``T_world_base`` (4, 4) maps base coordinates to world
coordinates; link i's frame has its origin at joint i and x along the link.  Angles in radians,
lengths in metres.
"""
from __future__ import annotations

import numpy as np

from explore3d.arm.spec import ArmSpec


def link_frames_planar(spec: ArmSpec, q) -> tuple[np.ndarray, np.ndarray]:
    """Planar link frames in the base frame.

    Args:
        spec: the arm.
        q: (..., n) joint angles, rad.

    Returns:
        origins: (..., n, 2) joint i's position in the base x-y plane, metres.
        headings: (..., n) link i's absolute angle about base +z, rad.
    """
    q = np.asarray(q, dtype=np.float64)
    if q.shape[-1] != spec.n_links:
        raise ValueError(f"q must have {spec.n_links} joint angles in its last axis; got shape {q.shape}")
    headings = np.cumsum(q, axis=-1)
    step = spec.link_length * np.stack([np.cos(headings), np.sin(headings)], axis=-1)
    origins = np.concatenate([np.zeros(step[..., :1, :].shape), np.cumsum(step[..., :-1, :], axis=-2)], axis=-2)
    return origins, headings


def link_transforms(spec: ArmSpec, q, T_world_base=None) -> np.ndarray:
    """(..., n, 4, 4) ``T_world_link`` for each link (identity base if ``T_world_base`` is None)."""
    origins, headings = link_frames_planar(spec, q)
    c, s = np.cos(headings), np.sin(headings)
    T = np.zeros(headings.shape + (4, 4))
    T[..., 0, 0], T[..., 0, 1] = c, -s
    T[..., 1, 0], T[..., 1, 1] = s, c
    T[..., 2, 2] = 1.0
    T[..., 3, 3] = 1.0
    T[..., 0, 3] = origins[..., 0]
    T[..., 1, 3] = origins[..., 1]
    if T_world_base is not None:
        T = np.asarray(T_world_base, dtype=np.float64) @ T
    return T


def face_points_local(spec: ArmSpec, n_along: int, n_height: int, faces=("inner",)) -> np.ndarray:
    """(k, 3) sample points on one link's faces in its own link frame, metres.

    ``inner`` is the +y face (towards the curl), ``outer`` the -y face.  ``n_along`` points evenly
    from x = 0 to x = L; ``n_height`` evenly from z = -H/2 to H/2 (1 gives the mid-plane z = 0).
    """
    if n_along < 2 or n_height < 1:
        raise ValueError(f"need n_along >= 2 and n_height >= 1; got {n_along}, {n_height}")
    xs = np.linspace(0.0, spec.link_length, n_along)
    zs = np.zeros(1) if n_height == 1 else np.linspace(-spec.link_height / 2, spec.link_height / 2, n_height)
    blocks = []
    for face in faces:
        if face not in ("inner", "outer"):
            raise ValueError(f"face must be 'inner' or 'outer'; got {face!r}")
        y = spec.link_width / 2 if face == "inner" else -spec.link_width / 2
        X, Z = np.meshgrid(xs, zs, indexing="ij")
        blocks.append(np.stack([X.ravel(), np.full(X.size, y), Z.ravel()], axis=-1))
    return np.concatenate(blocks, axis=0)


def link_surface_points(spec: ArmSpec, q, T_world_base=None, n_along: int = 5, n_height: int = 3,
                        faces=("inner",), face_offset: float = 0.0) -> np.ndarray:
    """World-frame surface points of every link.

    Args:
        q: (..., n) joint angles, rad.
        T_world_base: (4, 4) base pose, or None for the identity.
        n_along, n_height, faces: see :func:`face_points_local`.
        face_offset: metres to push each face along its own outward normal (the inner face
            towards the curl, i.e. towards the object).  A calibrated "contact thickness" (the
            gap the simulation leaves between a touching face and the surface) is applied this way.

    Returns:
        (..., n, k, 3) points, metres, world frame; k = len(faces) * n_along * n_height.
    """
    local = face_points_local(spec, n_along, n_height, faces)
    if face_offset:
        local = local.copy()
        local[:, 1] += np.sign(local[:, 1]) * face_offset
    T = link_transforms(spec, q, T_world_base)
    return np.einsum("...ij,kj->...ki", T[..., :3, :3], local) + T[..., None, :3, 3]


def point_jacobian(spec: ArmSpec, q, link: int, point_local, T_world_base=None) -> np.ndarray:
    """(3, n) translational Jacobian, world frame, of a point fixed on ``link``.

    Column j maps joint j's velocity (rad/s) to the point's velocity (m/s): ``z x (p - o_j)`` for
    the joints up to ``link`` (all joint axes are the base z axis), 0 beyond.

    Args:
        q: (n,) joint angles, rad.
        link: index of the link the point is fixed to.
        point_local: (3,) the point in that link's frame, metres.
        T_world_base: (4, 4) base pose (None: identity).
    """
    q = np.asarray(q, dtype=np.float64)
    if q.shape != (spec.n_links,):
        raise ValueError(f"q must have shape ({spec.n_links},); got {q.shape}")
    if not 0 <= int(link) < spec.n_links:
        raise ValueError(f"link must be in [0, {spec.n_links - 1}]; got {link}")
    T = link_transforms(spec, q, T_world_base)
    p = T[link, :3, :3] @ np.asarray(point_local, dtype=np.float64) + T[link, :3, 3]
    z = T[0, :3, 2]
    J = np.zeros((3, spec.n_links))
    J[:, : link + 1] = np.cross(z, p - T[: link + 1, :3, 3]).T
    return J


def gravity_torques(spec: ArmSpec, q, T_world_base, gravity) -> np.ndarray:
    """(n,) joint torques, N m, that the links' weights exert on the joints at angles ``q`` (n,),
    rad, with the base at ``T_world_base`` (4, 4) and ``gravity`` (3,), m/s^2, world frame.

    ``tau_j = sum_{i >= j} z . ((c_i - o_j) x m_i g)`` with c_i link i's centre of mass (mid-link)
    and o_j joint j's position; a motor that applies ``-gravity_torques`` cancels the weights.
    """
    # Called every control step (the gravity feed-forward).  The arithmetic is exactly that of
    # link_transforms and np.cross (a test checks the results are bit-identical), without their
    # per-call overhead (measured: 45 -> 30 us a call); bit-identical matters: the chain's contact
    # dynamics turn a 1e-16 N m change of the feed-forward into different detections.
    q = np.asarray(q, dtype=np.float64)
    n, L = spec.n_links, spec.link_length
    if q.shape != (n,):
        raise ValueError(f"q must have shape ({n},); got {q.shape}")
    h = np.cumsum(q)
    c, s = np.cos(h), np.sin(h)
    step = L * np.stack([c, s], axis=-1)
    T = np.zeros((n, 4, 4))
    T[:, 0, 0], T[:, 0, 1] = c, -s
    T[:, 1, 0], T[:, 1, 1] = s, c
    T[:, 2, 2] = 1.0
    T[:, 3, 3] = 1.0
    T[1:, :2, 3] = np.cumsum(step[:-1], axis=0)
    T = np.asarray(T_world_base, dtype=np.float64) @ T
    com = T[:, :3, 3] + T[:, :3, 0] * (L / 2.0)
    f = spec.link_mass * np.asarray(gravity, dtype=np.float64)
    z = T[0, :3, 2]
    # torque of each link's weight about the world origin, projected on z; the moment about o_j is
    # that minus o_j x (sum of the distal weights)
    m_origin = _cross(com, f) @ z  # (n,)
    tail_m = np.cumsum(m_origin[::-1])[::-1]  # sum over i >= j
    count = np.arange(n, 0, -1)  # number of links i >= j
    tail_f = count[:, None] * f[None, :]
    return tail_m - _cross(T[:, :3, 3], tail_f) @ z


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """np.cross of (m, 3) ``a`` with (3,) or (m, 3) ``b``, the same arithmetic, (m, 3)."""
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
    out = np.empty((len(a), 3))
    out[:, 0] = a1 * b2 - a2 * b1
    out[:, 1] = a2 * b0 - a0 * b2
    out[:, 2] = a0 * b1 - a1 * b0
    return out
