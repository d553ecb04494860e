"""Forward kinematics of the planar chain and the surface points of its links (pure numpy).

Frames follow :mod:`explore3d.arm`: ``T_world_base`` (4, 4) maps base coordinates to world
coordinates; link i's frame has its origin at joint i and x along the link.  Angles in radians,
lengths in metres.
"""
from __future__ import annotations

import numpy as np

from .arm import ArmSpec


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
