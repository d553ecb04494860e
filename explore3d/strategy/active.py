"""Probes chosen from the current estimate (active exploration): where could the estimate still be
most wrong, and which wraps go there.

After a round of wraps the estimate (a hull of the contacts, carved by the swept free space) has
surface that no contact supports: facets bridging a concavity the chain spanned like a string,
and carving's cut faces where a swept slab ended.  A surface point ``d`` from the nearest contact
may lie up to about ``d`` off the true surface (a surface that turns by at most 45 degrees between
the contact and the point; the distance bounds the depth, it does not estimate it), so the
*volume at stake* of a patch is its area times ``d`` (:func:`surface_stake`).
:func:`unsupported_targets` samples the estimate's surface and picks, highest first, the points
whose neighbourhood (within the exclusion distance: what one probe's wraps settle) holds the most
volume at stake, apart from each other and from the targets already probed;
:func:`probe_poses` puts wrap planes through each target: planes containing its surface normal
(two orientations about it), the arm approaching from the side the normal points to, so the chain
sweeps down onto the unsupported surface (a facet bridging a concavity: one of them runs along the
concavity); and a plane across the normal, half a link height beneath the surface, whose slab is
the next one under it (a face carving left where a swept slab ended: the plane sweeps the slab
beside it).  Pure functions on numpy arrays; world frame, metres.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from explore3d.core.validate import check_field
from explore3d.geometry.directions import WrapPose, fibonacci_sphere, wrap_pose

__all__ = ["ProbeConfig", "surface_stake", "unsupported_targets", "probe_poses", "finger_poses"]


@dataclass(frozen=True)
class ProbeConfig:
    """Rounds of probes after the first wraps (SI units).

    Attributes:
        rounds: at most this many rounds of probes (0: none).
        targets: at most this many targets per round.
        orientations: wrap planes per target rotated evenly about the target's surface normal
            (all contain the normal).
        across: one more wrap plane per target, perpendicular to its normal, half a link height
            beneath the surface.
        min_distance_m: a surface sample of the estimate closer than this to a contact is never a
            target.  Default 0: no floor (issue 24: with the former floor of one link length,
            ``None``, the bunny and the duck got no target although all of their error lay within
            a link of some contact).
        rank: how targets are chosen among the samples: ``"stake"`` (default), the most volume at
            stake (:func:`surface_stake`) within ``exclusion_m`` of the sample; ``"distance"``,
            the farthest from every contact (the rule before issue 24).
        stop_stake: stop before a round when the estimate's volume at stake is below this fraction
            of its volume (0, default: every round runs; the fraction measured after the first
            wraps is in BENCHMARKS.md).
        exclusion_m: targets lie at least this far from each other and from earlier rounds'
            targets; None: the link height (the thickness of the slab one wrap sweeps).
        min_change: stop when a round changed the estimate's volume by less than this fraction
            (default 0: every round runs while targets are left; measured on the L-block, a 1%
            rule stopped after one round at 11.5% volume error (114 wraps) where three rounds gave
            10.5% (150 wraps): a round aimed at one region may change little while the next, aimed
            elsewhere, does).
        samples: surface samples of the estimate per round (seeded).
        fingers: finger probes (:func:`finger_poses`) at up to this many targets per round
            (their own, chosen like the wraps' but apart from earlier fingers' targets; 0: none):
            the straight arm laid alongside the target's surface through space the estimate leaves
            empty (a channel the free space carved), brought onto the surface by the sweep.
            Default 12: measured on the concave and non-convex sets (BENCHMARKS.md) the U-channel
            went from 23.1 to 18.1%, the torus 30.8 to 21.8%, the T prism 15.8 to 12.9%, the
            others within a point, the cube 2.25 to 2.02%, for 7-36 one-attempt wraps more.
        pokes: tip pokes (:mod:`explore3d.strategy.poke`) at up to this many targets per round
            (chosen like the wraps' but apart from earlier pokes' targets; 0: none): the tip
            brought along the estimate's inward normal onto the target and up to the target's
            distance from every contact plus a link width past it.  Default 12, measured against
            none (BENCHMARKS.md, two noise seeds each; the cube five): the non-convex set's
            median 14.6 -> 11.2% and 13.3 -> 10.1%, the cube's 2.42 -> 1.92%, better on the
            sphere, box, capsule, U-channel and star prism too; worse on the cylinder (+0.1 to
            +0.5 points) and the cone (+0.5 to +0.7); about 2% more physics steps.
        slides: after each poke's touch the tip follows the surface this many steps of 3 mm each
            way (:func:`explore3d.strategy.poke.slide_tip`: contour following, a moment read at
            each step; 0, default: none).
    """

    rounds: int = 3
    targets: int = 6
    orientations: int = 2
    across: bool = True
    min_distance_m: float | None = 0.0
    rank: str = "stake"
    stop_stake: float = 0.0
    exclusion_m: float | None = None
    min_change: float = 0.0
    samples: int = 4000
    fingers: int = 12
    pokes: int = 12
    slides: int = 0

    def __post_init__(self):
        for name, lo in (("rounds", 0), ("targets", 1), ("orientations", 1), ("samples", 10)):
            check_field(self, name, lo, integer=True)
        if self.min_distance_m is not None:
            check_field(self, "min_distance_m", 0, "m (or None)")
        if self.exclusion_m is not None:
            check_field(self, "exclusion_m", 0, "m (or None)", strict=True)
        if self.rank not in ("stake", "distance"):
            raise ValueError(f"ProbeConfig.rank must be 'stake' or 'distance'; got {self.rank!r}")
        check_field(self, "min_change", 0)
        check_field(self, "stop_stake", 0)
        if not isinstance(self.across, bool):
            raise ValueError(f"ProbeConfig.across must be True or False; got {self.across!r}")
        check_field(self, "fingers", 0, integer=True)
        check_field(self, "pokes", 0, integer=True)
        check_field(self, "slides", 0, integer=True)
        if self.slides and not self.pokes:
            raise ValueError(f"ProbeConfig.slides follows the tip after each poke: set pokes >= 1 (got pokes=0, "
                             f"slides={self.slides})")


def surface_stake(mesh, contacts, samples: int = 4000, seed: int = 0):
    """Where the estimate could still be wrong: seeded surface samples of ``mesh`` (the estimate,
    closed trimesh, metres) and each one's distance to the nearest of ``contacts`` (m, 3), m.

    A sample ``d`` from every contact may lie up to about ``d`` off the true surface (the surface
    turning by at most 45 degrees on the way from the contact), so its share of the volume at stake
    is its area times ``d``; the estimate's volume at stake is ``area_m2 * d.sum()``.

    Returns:
        points (n, 3), outward unit normals (n, 3), distances d (n,) m (inf with no contact), and
        the area each sample stands for, m^2 (the estimate's area over ``samples``).
    """
    P, fi = trimesh.sample.sample_surface(mesh, samples, seed=seed)
    C = np.asarray(contacts, dtype=float).reshape(-1, 3)
    d = cKDTree(C).query(P)[0] if len(C) else np.full(len(P), np.inf)
    return P, mesh.face_normals[fi], d, float(mesh.area) / len(P)


def unsupported_targets(mesh, contacts, min_distance_m: float, exclusion_m: float, k: int, previous=None,
                        samples: int = 4000, seed: int = 0, rank: str = "distance"):
    """Up to ``k`` points of the estimate's surface least supported by contacts.

    Args:
        mesh: the estimate (closed trimesh, metres).
        contacts: (m, 3) contact points, m.
        min_distance_m: samples this close to a contact, or closer, are never targets.
        exclusion_m: targets keep more than this distance from each other and from ``previous``.
        previous: (p, 3) earlier targets, m (or None).
        rank: ``"distance"``: farthest from every contact first; ``"stake"``: the most volume at
            stake (:func:`surface_stake`, area x distance, m^3) within ``exclusion_m`` of the
            sample first (a wide bridged patch before a lone far point).

    Returns:
        points (t, 3), outward unit normals (t, 3), and each one's distance to the nearest
        contact (t,), m; in the order of ``rank``.
    """
    if rank not in ("stake", "distance"):
        raise ValueError(f"rank must be 'stake' or 'distance'; got {rank!r}")
    P, N, d, area = surface_stake(mesh, contacts, samples, seed)
    ok = d > min_distance_m
    if previous is not None and len(previous):
        ok &= cKDTree(np.asarray(previous, float).reshape(-1, 3)).query(P)[0] > exclusion_m
    if rank == "stake" and np.isfinite(d).all():
        pairs = cKDTree(P).query_pairs(exclusion_m, output_type="ndarray")
        key = area * d.copy()
        np.add.at(key, pairs[:, 0], area * d[pairs[:, 1]])
        np.add.at(key, pairs[:, 1], area * d[pairs[:, 0]])
    else:
        key = d
    idx = np.nonzero(ok)[0]
    idx = idx[np.lexsort((idx, -key[idx]))]  # highest first, ties by index (deterministic)
    chosen: list[int] = []
    for i in idx:
        if len(chosen) >= k:
            break
        if all(np.linalg.norm(P[i] - P[j]) > exclusion_m for j in chosen):
            chosen.append(int(i))
    c = np.array(chosen, dtype=int)
    return P[c].reshape(-1, 3), N[c].reshape(-1, 3), d[c]


def probe_poses(targets, normals, centre, radius: float, arm_width: float, orientations: int = 2,
                clearance: float = 0.01, label: str = "probe", across_depth_m: float | None = None) -> list[WrapPose]:
    """Wrap poses through each target point (t, 3): planes containing its outward normal (t, 3),
    ``orientations`` of them evenly rotated about it, the straight arm starting on the normal's
    side of the rough bound (centre (3,), radius m) so the chain sweeps towards the target; and,
    unless ``across_depth_m`` is None, a plane perpendicular to the normal ``across_depth_m``
    beneath the target, the arm starting on the side away from the rough centre."""
    centre = np.asarray(centre, dtype=float)
    out = []
    for ti, (p, ns) in enumerate(zip(np.asarray(targets, float), np.asarray(normals, float))):
        ns = ns / np.linalg.norm(ns)
        ref = np.array([1.0, 0.0, 0.0]) if abs(ns[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        u = ref - ns * (ref @ ns)
        u /= np.linalg.norm(u)
        v = np.cross(ns, u)
        for oi in range(orientations):
            ang = math.pi * oi / orientations
            m = math.cos(ang) * u + math.sin(ang) * v  # the plane's normal, perpendicular to ns
            offset = float((p - centre) @ m)
            r = math.sqrt(max(radius * radius - offset * offset, (0.2 * radius) ** 2))
            y = -ns  # the arm starts at -y of the wrap frame: on the normal's side
            x = np.cross(y, m)
            R = np.stack([x, y, m], axis=1)
            out.append(wrap_pose(centre, R, offset, r, arm_width, clearance, r, m, ang,
                                 f"{label} t{ti} o{oi} s{offset * 1000:+.0f}mm"))
        if across_depth_m is not None:
            offset = float((p - across_depth_m * ns - centre) @ ns)
            r = math.sqrt(max(radius * radius - offset * offset, (0.2 * radius) ** 2))
            w = (p - centre) - ((p - centre) @ ns) * ns  # the target's side within the plane
            y = -(w / np.linalg.norm(w)) if np.linalg.norm(w) > 1e-9 else -u
            x = np.cross(y, ns)
            out.append(wrap_pose(centre, np.stack([x, y, ns], axis=1), offset, r, arm_width, clearance, r, ns, 0.0,
                                 f"{label} t{ti} across s{offset * 1000:+.0f}mm"))
    return out


def finger_poses(targets, normals, estimate, centre, radius: float, spec, gap_m: float = 0.003,
                 directions: int = 200, max_tilt: float = math.radians(15.0), step_m: float = 0.002,
                 label: str = "finger") -> list[WrapPose]:
    """Finger probes: for each target (t, 3) on the estimate with outward normal (t, 3), the
    straight arm laid alongside the target's surface, its tip ``gap_m`` plus half a link width off
    it, through space the estimate (closed trimesh, metres) leaves empty -- a channel carved by the
    free space, or the outside -- so the sweep brings the arm onto the surface from within a
    concavity the wraps only bridged, and the space it sweeps on the way reaches the surface.

    Candidate arm directions ``e`` (the arm's +x, base to tip) are ``directions`` evenly spread
    unit vectors (:func:`~explore3d.geometry.directions.fibonacci_sphere`) within ``max_tilt`` of the
    target's tangent plane.  One is feasible when the straight arm's cross-section (link width x
    height, plus ``gap_m`` all round), sampled every ``step_m`` along it, lies wholly outside the
    estimate and its base outside the rough bound (centre (3,), radius m).  Of the feasible ones
    the arm that runs longest alongside the estimate's surface (stations within a link width plus
    two gaps of it) is taken, then the least tilted, then the first; a target with none gets no
    finger.  The arm curls towards the surface: the wrap frame's +y is the normal's opposite
    projected across ``e``.  Pure geometry on the estimate (what the robot believes).
    """

    centre = np.asarray(centre, dtype=float)
    L = spec.n_links * spec.link_length
    half_w, half_h = spec.link_width / 2 + gap_m, spec.link_height / 2 + gap_m
    E = fibonacci_sphere(directions)
    s = np.arange(0.0, L + 1e-12, step_m)
    S, _ = trimesh.sample.sample_surface(estimate, 4000, seed=0)
    near = cKDTree(S)
    corners = [(a, b) for a in (-half_w, 0.0, half_w) for b in (-half_h, 0.0, half_h)]
    out = []
    for ti, (p, n) in enumerate(zip(np.asarray(targets, float), np.asarray(normals, float))):
        n = n / np.linalg.norm(n)
        tip = p + half_w * n  # half a link width plus the gap off the surface
        tilt = np.abs(E @ n)
        best = None
        for i in np.nonzero(tilt <= math.sin(max_tilt))[0]:
            e = E[i]
            y = -(n - (n @ e) * e)
            y /= np.linalg.norm(y)
            m = np.cross(e, y)
            base = tip - L * e
            if np.linalg.norm(base - centre) <= radius:
                continue
            line = base + s[:, None] * e
            line = line[np.linalg.norm(line - centre, axis=1) <= radius + half_w + half_h]
            if not len(line):
                continue
            if estimate.contains(np.concatenate([line + a * y + b * m for a, b in corners])).any():
                continue
            along = int((near.query(line)[0] <= spec.link_width + 2 * gap_m).sum())
            key = (-along, float(tilt[i]), int(i))
            if best is None or key < best[0]:
                best = (key, e, y, m, base, i)
        if best is not None:
            _, e, y, m, base, i = best
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = np.stack([e, y, m], axis=1), base
            out.append(WrapPose(T, m, float((base - centre) @ m), 0.0, f"{label} t{ti} e{i}"))
    return out
