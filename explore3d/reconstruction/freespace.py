"""Free space: what the arm's links swept through holds no object (pure numpy).

A wrap's links move in one plane, the base frame's x-y plane, and each link is a box
``[0, L] x [-W/2, W/2] x [-H/2, H/2]`` in its link frame (:mod:`explore3d.arm.spec`).  The space a
wrap swept is therefore a slab ``|z| <= H/2`` of its base frame times a planar region: the union
of the link rectangles at every reading.  :func:`swept_area` rasterises that region on a pixel
grid around the rough bound from the *measured* joint angles, the arm's own model and the known
base pose, nothing else: a real arm knows as much.  :func:`is_free` answers, for points in the
world frame, whether some wrap swept through them; :mod:`explore3d.reconstruction.carve` removes that space from
an estimate.

Safety margin: a pixel is marked free only when its centre lies inside a link rectangle shrunk
by ``margin_m`` across its width and at the chain's two free ends (the contact margin of the
simulator, the encoder's resolution times the reach, and the links' small penetration under
load); the slab is shrunk by the same margin.  Not along the links at the joints between them,
where the next link continues the chain (shrinking there would leave an unswept ring along every
joint's path); at a bend, the end face of a link is exposed only on the bend's outer side, away
from the curl and the object it wraps.  Frames: ``T_world_base`` (4, 4) maps base to world coordinates; lengths in metres.
"""
from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np

from explore3d.arm.kinematics import link_frames_planar
from explore3d.arm.spec import ArmSpec
from explore3d.core.io import atomic_write_bytes

__all__ = ["SweptArea", "swept_area", "is_free", "save_swept", "load_swept", "DEFAULT_PIXEL_M", "DEFAULT_MARGIN_M"]

#: pixel edge of the swept-area grids, m
DEFAULT_PIXEL_M = 1.0e-3
#: clearance kept between a free pixel's centre and the link's faces, m (the simulator's 0.3 mm
#: contact margin, about 0.2 mm of encoder resolution at 0.3 m reach, and penetration under load)
DEFAULT_MARGIN_M = 0.5e-3


@dataclass(frozen=True)
class SweptArea:
    """The region one wrap's links swept through.

    Attributes:
        T_world_base: (4, 4) the wrap's base pose.
        origin_m: (2,) base-frame x, y of the centre of pixel (0, 0), m.
        pixel_m: pixel edge, m.
        free: (nx, ny) bool, pixel (i, j) (centre ``origin_m + (i, j) pixel_m``) lies inside a
            link rectangle shrunk by ``margin_m`` at some reading.
        half_height_m: the slab |z| <= half_height_m (base frame) in which the area is free, m.
        margin_m: the margin the link boxes were shrunk by, m.
    """

    T_world_base: np.ndarray
    origin_m: np.ndarray
    pixel_m: float
    free: np.ndarray
    half_height_m: float
    margin_m: float

    @property
    def free_area_m2(self) -> float:
        return float(self.free.sum()) * self.pixel_m ** 2


def _lattice(spec: ArmSpec, shrink: float, spacing: float, first: bool, last: bool) -> np.ndarray:
    """(k, 2) points filling a link rectangle, link frame, m: shrunk by ``shrink`` across its width
    and at the chain's free ends (the base end of the ``first`` link, the tip end of the ``last``);
    not at the joints between links, where the next link's rectangle continues the chain."""
    x0, x1 = (shrink if first else 0.0), spec.link_length - (shrink if last else 0.0)
    y0, y1 = -spec.link_width / 2 + shrink, spec.link_width / 2 - shrink
    if x1 < x0 or y1 < y0:
        return np.zeros((0, 2))
    nx = max(2, int(np.ceil((x1 - x0) / spacing)) + 1)
    ny = max(2, int(np.ceil((y1 - y0) / spacing)) + 1)
    X, Y = np.meshgrid(np.linspace(x0, x1, nx), np.linspace(y0, y1, ny), indexing="ij")
    return np.column_stack([X.ravel(), Y.ravel()])


def swept_area(spec: ArmSpec, q, T_world_base, centre, radius: float, pixel_m: float = DEFAULT_PIXEL_M,
               margin_m: float = DEFAULT_MARGIN_M) -> SweptArea:
    """The region the links swept through over the readings ``q``, around the rough bound.

    Args:
        spec: the arm's model.
        q: (t, n) measured joint angles of every reading of the wrap, rad.
        T_world_base: (4, 4) the wrap's known base pose.
        centre, radius: the rough bound (3,) and its radius, m; only the part of the plane within
            it is rasterised.
        pixel_m: pixel edge, m.
        margin_m: clearance kept from the link faces, m (see the module docstring).

    Returns:
        a :class:`SweptArea` (all False where the wrap's plane misses the bound).
    """
    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    T = np.asarray(T_world_base, dtype=np.float64)
    if pixel_m <= 0 or margin_m < 0:
        raise ValueError(f"pixel_m must be > 0 and margin_m >= 0; got {pixel_m}, {margin_m}")
    cb = T[:3, :3].T @ (np.asarray(centre, dtype=np.float64) - T[:3, 3])
    half = spec.link_height / 2 - margin_m
    r2 = float(radius) ** 2 - float(cb[2]) ** 2
    r = float(np.sqrt(r2)) if r2 > 0 else 0.0
    n_pix = max(1, int(np.ceil(2 * r / pixel_m)) + 1)
    origin = cb[:2] - (n_pix - 1) / 2 * pixel_m
    free = np.zeros((n_pix, n_pix), dtype=bool)
    if r > 0 and half > 0 and len(q):
        # points a pixel-half-diagonal deeper than the margin: the pixel holding one has its centre
        # inside the rectangle shrunk by margin_m
        shrink, spacing = margin_m + pixel_m * np.sqrt(0.5), pixel_m / np.sqrt(2.0)
        n = spec.n_links
        lattices = [_lattice(spec, shrink, spacing, i == 0, i == n - 1) for i in range(n)]
        origins, headings = link_frames_planar(spec, q)  # (t, n, 2), (t, n)
        # links whose rectangle can reach the disc (centre distance < r + half the diagonal)
        mid = origins + 0.5 * spec.link_length * np.stack([np.cos(headings), np.sin(headings)], axis=-1)
        reach = r + 0.5 * np.hypot(spec.link_length, spec.link_width)
        near = np.linalg.norm(mid - cb[:2], axis=-1) < reach
        ti, li = np.nonzero(near)
        if len(ti):
            # skip repeated poses (settling): a link whose frame moved less than a tenth of a pixel
            o, h = origins[ti, li], headings[ti, li]
            key = np.column_stack([li, np.round(o / (0.1 * pixel_m)), np.round(h * spec.link_length / (0.1 * pixel_m))])
            _, keep = np.unique(key, axis=0, return_index=True)
            o, h, li = o[keep], h[keep], li[keep]
            c, s = np.cos(h), np.sin(h)
            for link in np.unique(li):
                pts = lattices[link]
                idx = np.nonzero(li == link)[0]
                for chunk in range(0, len(idx), 256):
                    j_ = idx[chunk:chunk + 256]
                    oc, cc, sc = o[j_], c[j_], s[j_]
                    x = oc[:, None, 0] + cc[:, None] * pts[None, :, 0] - sc[:, None] * pts[None, :, 1]
                    y = oc[:, None, 1] + sc[:, None] * pts[None, :, 0] + cc[:, None] * pts[None, :, 1]
                    i = np.rint((x.ravel() - origin[0]) / pixel_m).astype(np.int64)
                    j = np.rint((y.ravel() - origin[1]) / pixel_m).astype(np.int64)
                    ok = (i >= 0) & (i < n_pix) & (j >= 0) & (j < n_pix)
                    free[i[ok], j[ok]] = True
    return SweptArea(T_world_base=T.copy(), origin_m=origin, pixel_m=float(pixel_m), free=free,
                     half_height_m=float(max(half, 0.0)), margin_m=float(margin_m))


def is_free(areas, points) -> np.ndarray:
    """(m,) bool: which world points (m, 3), metres, lie in space some wrap swept through."""
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.zeros(len(P), dtype=bool)
    for a in areas:
        if not a.free.any():
            continue
        R, t = a.T_world_base[:3, :3], a.T_world_base[:3, 3]
        # the slab first (one dot product per point), then the pixels of the points in it
        idx = np.nonzero(np.abs(P @ R[:, 2] - t @ R[:, 2]) <= a.half_height_m)[0]
        idx = idx[~out[idx]]
        if not len(idx):
            continue
        pb = (P[idx] - t) @ R[:, :2]
        i = np.rint((pb[:, 0] - a.origin_m[0]) / a.pixel_m).astype(np.int64)
        j = np.rint((pb[:, 1] - a.origin_m[1]) / a.pixel_m).astype(np.int64)
        ok = (i >= 0) & (i < a.free.shape[0]) & (j >= 0) & (j < a.free.shape[1])
        hit = np.zeros(len(idx), dtype=bool)
        hit[ok] = a.free[i[ok], j[ok]]
        out[idx[hit]] = True
    return out


def save_swept(areas, path) -> None:
    """Write swept areas to ``path`` (.npz, atomically): what ``explore3d reconstruct --free-space``
    reads to carve an estimate as the run did."""
    arrays = {"T_world_base": np.array([a.T_world_base for a in areas]).reshape(-1, 4, 4),
              "origin_m": np.array([a.origin_m for a in areas]).reshape(-1, 2),
              "pixel_m": np.array([a.pixel_m for a in areas], dtype=float),
              "half_height_m": np.array([a.half_height_m for a in areas], dtype=float),
              "margin_m": np.array([a.margin_m for a in areas], dtype=float),
              "shape": np.array([a.free.shape for a in areas], dtype=np.int64).reshape(-1, 2),
              "free_bits": np.packbits(np.concatenate([a.free.ravel() for a in areas]) if areas else np.zeros(0, bool))}
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    atomic_write_bytes(path, buf.getvalue())


def load_swept(path) -> list[SweptArea]:
    """Read swept areas written by :func:`save_swept`; ValueError naming the file if it is not one."""
    keys = ("T_world_base", "origin_m", "pixel_m", "half_height_m", "margin_m", "shape", "free_bits")
    try:
        with np.load(path, allow_pickle=False) as z:
            d = {k: z[k] for k in keys}
    except (OSError, ValueError, KeyError) as exc:
        raise ValueError(f"cannot read free space from {str(path)!r} ({exc}); pass the free_space.npz a run wrote") from None
    sizes = d["shape"].prod(axis=1)
    bits = np.unpackbits(d["free_bits"], count=int(sizes.sum())).astype(bool)
    out, at = [], 0
    for k in range(len(sizes)):
        out.append(SweptArea(T_world_base=d["T_world_base"][k], origin_m=d["origin_m"][k], pixel_m=float(d["pixel_m"][k]),
                             free=bits[at:at + sizes[k]].reshape(d["shape"][k]),
                             half_height_m=float(d["half_height_m"][k]), margin_m=float(d["margin_m"][k])))
        at += int(sizes[k])
    return out
