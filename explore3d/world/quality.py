"""Contact quality of an exploration, measured against the true mesh after the run (oracle).

EVALUATION ONLY.  Nothing here is, or may be, used by the robot: the functions take the true
object mesh and compare the recorded link geometry with it.  The exploration itself
(:mod:`explore3d.strategy.encircle`) never sees the object.  Distances come from :mod:`explore3d.geometry.sdf`; the
detection rule recomputed here is the detector's own (:class:`explore3d.feeling.detect.SweepDetector`).

Trajectory figures (delay, knock-off, trajectory penetration) need ``ExploreConfig(record=True)``.
The recorded trajectory holds the sweep steps only (not the settle steps between sweeps); the
joint swept at each recorded step is recovered from the references (:func:`swept_joints`).
"""
from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import asdict, dataclass

import numpy as np

from explore3d.arm.kinematics import link_surface_points, link_transforms
from explore3d.arm.spec import ArmSpec
from explore3d.feeling.detect import SweepDetector
from explore3d.geometry.sdf import (
    DETECTION_CONFIG_PITCH_M,
    PYBULLET_MESH_MARGIN_M,
    TRAJECTORY_PITCH_M,
    SignedDistance,
    _as_sdf,
    box_min_distance,
    face_min_distance,
)
from explore3d.strategy.explore import contact_points
from explore3d.world.replay import replay_wrap

__all__ = [
    "ContactQuality", "DetectionRecord", "FALSE_DETECTION_TOL_M", "TOUCH_TOL_M", "contact_gaps", "contact_links",
    "contact_point_gaps", "contact_quality", "detection_records", "exploration_points_3d", "sweep_segments",
    "swept_joints",
]

#: A detection counts as *false* when no part of the moving chain (the swept link and all links
#: distal to it) is within this distance of the surface at the detection step, metres.  Twice the
#: mesh margin: a touching link is at ~1 mm, the largest resting gaps measured are ~1.3 mm.
FALSE_DETECTION_TOL_M = 2.0e-3

#: A link *touches* the object (for the detection delay) when its box is within this distance of
#: the surface, metres: the mesh margin (where PyBullet's contact constraint acts) plus 0.2 mm for
#: the sampling error of the trajectory grid (measured <= 0.2 mm near the surface at 2.5 mm pitch).
TOUCH_TOL_M = PYBULLET_MESH_MARGIN_M + 0.2e-3

# --- trajectory bookkeeping ------------------------------------------------------------------------
def swept_joints(trajectory_ref) -> np.ndarray:
    """(t,) int: the joint swept at each recorded step, from the references (t, n), rad.

    During joint k's sweep only reference k moves (it increases every step); at the first step of
    a sweep the previous joint's reference also jumps to its hold angle, and after a self-contact
    a joint beyond it may have been turned back (:func:`explore3d.strategy.encircle.retreat`, between
    recorded steps).  So the swept joint is the highest-numbered joint whose reference increased
    since the previous step (all references start at 0); a step where none did keeps the previous
    joint.
    """
    R = np.asarray(trajectory_ref, dtype=np.float64)
    if R.ndim != 2:
        raise ValueError(f"trajectory_ref must have shape (t, n); got {R.shape}")
    prev = np.vstack([np.zeros((1, R.shape[1])), R[:-1]])
    changed = R > prev
    n = R.shape[1]
    last = np.where(changed.any(axis=1), n - 1 - np.argmax(changed[:, ::-1], axis=1), -1)
    sw = np.maximum.accumulate(np.maximum(last, 0)) if len(last) else last
    return sw.astype(int)


def attempt_swept_joints(attempt) -> np.ndarray:
    """(t,) int: the joint swept at each recorded step of ``attempt``: its ``trajectory_joint`` when
    it has one (the curl-back's moves between sweeps change references beyond the swept joint),
    else recovered from its references by :func:`swept_joints`."""
    tj = getattr(attempt, "trajectory_joint", None)
    return np.asarray(tj, dtype=int) if tj is not None else swept_joints(attempt.trajectory_ref)


def sweep_segments(attempt) -> dict[int, tuple[int, int]]:
    """{joint k: (first row, last row)} of each recorded sweep of an attempt (rows of
    ``attempt.trajectory``, inclusive).  The last row of a sweep is its detection step."""
    if attempt.trajectory is None or attempt.trajectory_ref is None:
        raise ValueError("the attempt has no trajectory; explore with ExploreConfig(record=True)")
    sw = attempt_swept_joints(attempt)
    out = {}
    if len(sw) == 0:
        return out
    cuts = np.flatnonzero(np.diff(sw)) + 1
    starts = np.concatenate([[0], cuts])
    ends = np.concatenate([cuts - 1, [len(sw) - 1]])
    for s, e in zip(starts, ends):
        out[int(sw[s])] = (int(s), int(e))
    return out


@dataclass(frozen=True)
class DetectionRecord:
    """One detected contact (a sweep ended by CONTACT), measured against the truth.

    Attributes:
        wrap, attempt, joint: where it happened.
        detect_row: row of the attempt's trajectory at the detection step.
        chain_distance_m: distance of the moving chain (the swept link and all distal links) to
            the surface at the detection step, metres, from :func:`box_min_distance` with
            ``decide_only``: whether it is within ``cutoff_m`` is decided exactly (to the 1 mm
            grid); the value itself may come from a coarser grid (error <= its covering radius).
        arm_distance_m: the same for the whole arm.
        nearest_link: the moving-chain link nearest the surface at detection.
        touch_row: first row of this sweep at which the moving chain was within the touch
            tolerance, or -1 if it never was.
        delay_steps: ``detect_row - touch_row`` (-1 if never touched).
        trigger: which joint's error left its band at detection (``joint`` itself = the swept
            joint's lag; another index = that joint's error change); -1 when the recomputed
            signals stay inside the band (without a replay the pre-sweep error is not recorded
            and the first sweep row's error stands in for it).
        trigger_ratio: the triggering signal divided by its band (>= 1 at a clean detection).
        sweep_rows: number of recorded steps of the sweep.
    """

    wrap: int
    attempt: int
    joint: int
    detect_row: int
    chain_distance_m: float
    arm_distance_m: float
    nearest_link: int
    touch_row: int
    delay_steps: int
    trigger: int
    trigger_ratio: float
    sweep_rows: int

    def to_dict(self) -> dict:
        return asdict(self)


def _trigger(att, band, k: int, s: int, e: int, base_err=None, watch_held: bool = True) -> tuple[int, float]:
    """The detector's signals (:class:`explore3d.feeling.detect.SweepDetector`) at row e of sweep k (rows
    s..e), recomputed from the recorded trajectory; return (joint, signal / band), joint -1 when
    every signal is inside its band.

    ``base_err`` (n,) is the joint error q_ref - q just before the sweep (rad); the recording
    does not hold it (settle steps are not recorded), so by default the first sweep row's error
    stands in for it (the robot log of a recorded exploration gives the exact one).
    ``watch_held``: as ``ControlConfig.watch_held``."""
    Q, R = att.trajectory, att.trajectory_ref
    if e - s < 1:
        return -1, 0.0
    det = SweepDetector(k, R[s], Q[s], watch_held)
    if base_err is not None:
        det.base_err = np.asarray(base_err, dtype=np.float64)
    for t in (e - 1, e):
        lag, sig = det.update(R[t - 1, k], R[t], Q[t])
    j, r = SweepDetector.ratio(band, k, lag, sig)
    return (j if r >= 1.0 else -1), r


def _first_touch(spec, att, sdf, k: int, s: int, e: int, touch_tol_m: float, chunk: int = 24) -> int:
    """First row in s..e at which links k..n-1 are within ``touch_tol_m`` (trajectory grid), or -1."""
    for a in range(s, e + 1, chunk):
        b = min(e + 1, a + chunk)
        Tm = np.asarray(att.T_world_base) @ link_transforms(spec, att.trajectory[a:b])[:, k:]
        d, _, _ = box_min_distance(spec, Tm.reshape(-1, 4, 4), sdf, cutoff_m=touch_tol_m,
                                   pitches_m=(5.0e-3, TRAJECTORY_PITCH_M), decide_only=True)
        hit = np.flatnonzero(d.reshape(b - a, -1).min(axis=1) <= touch_tol_m)
        if hit.size:
            return int(a + hit[0])
    return -1


def detection_records(exploration, mesh, touch_tol_m: float = TOUCH_TOL_M, cutoff_m: float = FALSE_DETECTION_TOL_M,
                      exact_triggers: bool = False, wraps=None, replays: dict | None = None) -> list[DetectionRecord]:
    """Every detected contact of a recorded exploration, measured against ``mesh`` (the true
    closed trimesh, world frame, metres, or a :class:`SignedDistance` of it).

    Args:
        touch_tol_m: see :data:`TOUCH_TOL_M`.
        cutoff_m: distances at detection are resolved finely up to this, metres.
        exact_triggers: re-simulate every wrap (:func:`replay_wrap`, as long again as the
            exploration; needs the mesh) for the exact pre-sweep joint errors behind ``trigger``.
        wraps: indices of the wraps to measure (None: all).
        replays: {wrap: :class:`WrapReplay`} already computed (used instead of re-simulating).
    """
    sdf = _as_sdf(mesh)
    spec = exploration.spec
    watch_held = bool(getattr(exploration.config.control, "watch_held", True))
    out = []
    for wi in (range(exploration.n_wraps) if wraps is None else wraps):
        atts = exploration.attempts[wi]
        rp = (replays or {}).get(wi)
        if rp is None and exact_triggers:
            rp = replay_wrap(exploration, getattr(sdf, "mesh", mesh), wi)
        base = rp.base_err if rp is not None else None
        for ai, att in enumerate(atts):
            segs = sweep_segments(att)
            det = [k for k in range(spec.n_links) if att.contact[k]]
            if not det:
                continue
            missing = [k for k in det if k not in segs]
            if missing:
                raise ValueError(f"wrap {wi} attempt {ai}: joints {missing} detected contact but have no recorded sweep")
            rows = np.array([segs[k][1] for k in det])
            Tl = link_transforms(spec, att.trajectory[rows], att.T_world_base)  # (d, n, 4, 4)
            dist, _, _ = box_min_distance(spec, Tl.reshape(-1, 4, 4), sdf, cutoff_m=cutoff_m,
                                          pitches_m=(5.0e-3, TRAJECTORY_PITCH_M, DETECTION_CONFIG_PITCH_M),
                                          decide_only=True)
            dist = dist.reshape(len(det), spec.n_links)
            for i, k in enumerate(det):
                s, e = segs[k]
                chain = dist[i, k:]
                touch = _first_touch(spec, att, sdf, k, s, e, touch_tol_m)
                b = base[ai].get(k) if base is not None else None
                trig, ratio = _trigger(att, exploration.band, k, s, e, b, watch_held)
                out.append(DetectionRecord(
                    wrap=wi, attempt=ai, joint=k, detect_row=e, chain_distance_m=float(chain.min()),
                    arm_distance_m=float(dist[i].min()), nearest_link=int(k + np.argmin(chain)),
                    touch_row=touch, delay_steps=(e - touch) if touch >= 0 else -1,
                    trigger=trig, trigger_ratio=ratio, sweep_rows=e - s + 1))
    return out


# --- final configurations --------------------------------------------------------------------------
def _check_final(spec: ArmSpec, q, T_world_base, contact):
    q = np.asarray(q, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != spec.n_links or not np.isfinite(q).all():
        raise ValueError(f"q must be a finite (m, {spec.n_links}) array of joint angles; got shape {q.shape}")
    contact = np.asarray(contact, dtype=bool)
    if contact.shape != q.shape:
        raise ValueError(f"contact must have the shape of q {q.shape}; got {contact.shape}")
    T = np.asarray(T_world_base, dtype=np.float64)
    T = np.broadcast_to(T, (q.shape[0], 4, 4)) if T.shape == (4, 4) else T
    if T.shape != (q.shape[0], 4, 4):
        raise ValueError(f"T_world_base must have shape (4, 4) or ({q.shape[0]}, 4, 4); got {T.shape}")
    return q, T, contact


def contact_links(spec: ArmSpec, q, T_world_base, contact, sdf,
                  touch_m: float = FALSE_DETECTION_TOL_M) -> tuple[np.ndarray, np.ndarray]:
    """The link in contact behind every contact-flagged joint of final configurations.

    Joint k's contact means something on links k..n-1 touches.  The contact link is the most
    proximal of those that is within ``touch_m`` of the surface and nearer than its neighbours
    in k..n-1 (a local minimum of the distance along the chain: one link per place where the
    chain meets the object, not a neighbour that is merely close to it); if there is none, the
    nearest of k..n-1 (the flag was a false detection).  Taking the most proximal contact rather
    than the nearest link keeps the contacts of a wrap apart instead of always picking whichever
    link of the wrap happens to be a few micrometres closer.

    Args:
        spec: the arm.
        q: (m, n) joint angles, rad.
        T_world_base: (m, 4, 4) base poses, world frame (or one (4, 4) for all).
        contact: (m, n) bool, the contact flags.
        sdf: :class:`SignedDistance` (or mesh, or callable (..., 3) -> (...) metres) of the object.
        touch_m: metres.

    Returns:
        row: (c,) int, the configuration (row of ``q``) of each flagged joint, in row-major order.
        link: (c,) int, the link taken to be in contact.
    """
    q, T, contact = _check_final(spec, q, T_world_base, contact)
    sdf = _as_sdf(sdf)
    Tl = np.einsum("mij,mnjk->mnik", T, link_transforms(spec, q))  # (m, n, 4, 4)
    dist, _, _ = box_min_distance(spec, Tl.reshape(-1, 4, 4), sdf, cutoff_m=touch_m,
                                  pitches_m=(5.0e-3, TRAJECTORY_PITCH_M, DETECTION_CONFIG_PITCH_M), decide_only=True)
    dist = dist.reshape(q.shape)
    rows, ks = np.nonzero(contact)
    links = []
    for i, k in zip(rows, ks):
        d = dist[i, k:]
        prev = np.concatenate([[np.inf], d[:-1]])
        nxt = np.concatenate([d[1:], [np.inf]])
        near = np.flatnonzero((d <= touch_m) & (d <= prev) & (d <= nxt))
        links.append(int(k + (near[0] if near.size else np.argmin(d))))
    return rows.astype(int), np.array(links, dtype=int)


def contact_gaps(spec: ArmSpec, q, T_world_base, contact, sdf, face: str = "inner",
                 pitch_m: float = DETECTION_CONFIG_PITCH_M) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The gap behind every contact-flagged joint of final configurations: the minimum signed
    distance, metres, of the ``face`` (default the inner face, the one that gives the link
    points) of the contact link (:func:`contact_links`), sampled at ``pitch_m``.

    Args: as :func:`contact_links`.

    Returns:
        gap: (c,) metres, one per flagged joint (negative: the face is inside the object).
        row, link: (c,) int, as :func:`contact_links`.
    """
    q, T, contact = _check_final(spec, q, T_world_base, contact)
    sdf = _as_sdf(sdf)
    rows, links = contact_links(spec, q, T, contact, sdf)
    if rows.size == 0:
        return np.zeros(0), rows, links
    Tl = T[rows] @ link_transforms(spec, q[rows])[np.arange(rows.size), links]
    return face_min_distance(spec, Tl, sdf, face=face, pitch_m=pitch_m), rows, links


def exploration_points_3d(exploration) -> list[dict]:
    """The exploration's own link points, grouped: per attempt (wraps in order, then attempts) a
    dict {link: (k, 3) points, world frame, metres} for the links present in
    :attr:`Exploration.points` (for an exploration that hulled localised contacts, the link points
    of its contact-flagged links, :func:`explore3d.strategy.explore.contact_points`).  Planar explorations store x-y only; the height is restored from
    the kinematics (the points lie in the arm's plane).  Every stored point is checked against
    :func:`explore3d.arm.kinematics.link_surface_points` of its attempt's joint angles and config."""

    ex, cfg, spec = exploration, exploration.config, exploration.spec
    if cfg.points != "links":  # the hull took localised contacts: the link points of the same attempts
        cfg = dataclasses.replace(cfg, points="links")
        P, W, A, L = contact_points(spec, ex.attempts, cfg)
        ex = dataclasses.replace(ex, config=cfg, points=P, point_wrap=W, point_attempt=A, point_link=L)
    d = ex.points.shape[1]
    out = []
    for wi, atts in enumerate(ex.attempts):
        for ai, att in enumerate(atts):
            P = link_surface_points(spec, att.q, att.T_world_base, cfg.n_along, 1 if d == 2 else cfg.n_height,
                                    cfg.faces, cfg.face_offset)  # (n, k, 3)
            sel = (ex.point_wrap == wi) & (ex.point_attempt == ai)
            stored, links = ex.points[sel], ex.point_link[sel]
            groups = {}
            for j in np.unique(links):
                S = stored[links == j]
                if S.shape[0] != P.shape[1] or not np.allclose(S, P[j][:, :d], rtol=0.0, atol=1e-9):
                    raise ValueError(f"wrap {wi} attempt {ai} link {j}: the exploration's points do not follow "
                                     "from its joint angles and config")
                groups[int(j)] = P[j]
            out.append(groups)
    return out


def contact_point_gaps(exploration, sdf, unique: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Signed distance, metres, of the exploration's own link points behind every contact flag.

    For each contact-flagged joint of each attempt's final configuration, the contact link
    (:func:`contact_links`) and the smallest signed distance of that link's points in
    :attr:`Exploration.points` (so ``face_offset`` and the ``n_along`` x ``n_height`` sampling
    are included: this is the gap the reconstruction sees).  A contact link that gave no points
    gets NaN.

    Args:
        exploration: an :class:`~explore3d.strategy.explore.Exploration`.
        sdf: the true object: :class:`SignedDistance`, mesh or callable.
        unique: one value per (attempt, contact link) instead of one per flagged joint.

    Returns:
        gap: (c,) metres (NaN: no points); attempt: (c,) int (attempt index, wraps then
        attempts); link: (c,) int.
    """
    sdf = _as_sdf(sdf)
    spec = exploration.spec
    atts = [a for w in exploration.attempts for a in w]
    if not atts:
        return np.zeros(0), np.zeros(0, int), np.zeros(0, int)
    rows, links = contact_links(spec, np.array([a.q for a in atts]), np.array([a.T_world_base for a in atts]),
                                np.array([a.contact for a in atts]), sdf)
    if unique and rows.size:
        pairs = np.unique(np.stack([rows, links], axis=1), axis=0)
        rows, links = pairs[:, 0], pairs[:, 1]
    gaps = np.full(rows.size, np.nan)
    if rows.size == 0:
        return gaps, rows, links
    pts = exploration_points_3d(exploration)
    have = np.array([int(j) in pts[i] for i, j in zip(rows, links)], dtype=bool)
    if have.any():
        P = np.stack([pts[i][j] for i, j in zip(rows[have], links[have])])  # (c', k, 3)
        gaps[have] = sdf(P).min(axis=1)
    return gaps, rows, links


# --- the report --------------------------------------------------------------------------------------
def _q(x, p):
    x = np.asarray(x, dtype=float)
    return float(np.percentile(x, p)) if x.size else float("nan")


@dataclass(frozen=True)
class ContactQuality:
    """Quality figures of an exploration against the true object (SI units, named in fields).

    Detections are joint sweeps ended by a detected CONTACT.  The *moving chain* of joint k's
    sweep is link k and all links distal to it.

    Attributes:
        n_attempts, n_detections: counts.
        false_tol_m: the tolerance of the false-detection test.
        n_false, false_fraction: detections with no part of the moving chain within
            ``false_tol_m`` of the surface at the detection step (and their fraction).
        n_free_space, free_space_fraction: detections with no part of the whole arm within
            ``false_tol_m`` (the held proximal links are usually in contact, so this is rarer).
        false_joints: (n,) count of false detections per joint.
        false_distance_median_m: median moving-chain distance of the false detections.
        touch_tol_m: a link touches when within this distance (for the delay).
        n_delays: detections whose moving chain touched during the sweep (the delay's sample).
        delay_median_s, delay_max_s, delay_median_steps, delay_max_steps: time from the moving
            chain's first touch during the sweep to the detection.
        penetration_max_m, penetration_median_m: per final configuration the deepest penetration
            of any link box into the object (0 if none); max and median over attempts.
        penetration_trajectory_max_m: the deepest penetration along the recorded trajectories
            (every ``trajectory_stride``-th step).
        gap_median_m, gap_p90_m: signed distance of the inner face of the contact link (the
            most proximal touching link among the swept link and its distal links, see
            :func:`contact_links`) at the final configuration, over all detections.
        gap_true_median_m, gap_true_p90_m: the same over the detections that are not false.
        face_offset_m: the exploration's ``face_offset`` (it moves the points, not the links).
        point_gap_median_m, point_gap_p90_m: the smallest signed distance of the contact link's
            own points in :attr:`Exploration.points` (``face_offset`` and the ``n_along`` x
            ``n_height`` sampling included: the gap the reconstruction sees), over the
            detections that are not false.
        knock_off_held_max_rad: max |q - q_ref| over the trajectories of joints already held
            (proximal to the swept one).
        knock_off_distal_max_rad: the same for joints not yet swept (distal to the swept one).
        knock_off_held_median_rad: median over attempts of each attempt's held-joint maximum.
        knock_off_final_max_rad: max |q - q_ref| at the final configurations, all joints.
        trajectory_steps: recorded steps in all; trajectory_stride: the step of the trajectory
            penetration subsample.
        wall_s: wall-clock time of this evaluation, s.
    """

    n_attempts: int
    n_detections: int
    false_tol_m: float
    n_false: int
    false_fraction: float
    n_free_space: int
    free_space_fraction: float
    false_joints: tuple
    false_distance_median_m: float
    touch_tol_m: float
    n_delays: int
    delay_median_s: float
    delay_max_s: float
    delay_median_steps: float
    delay_max_steps: int
    penetration_max_m: float
    penetration_median_m: float
    penetration_trajectory_max_m: float
    gap_median_m: float
    gap_p90_m: float
    gap_true_median_m: float
    gap_true_p90_m: float
    face_offset_m: float
    point_gap_median_m: float
    point_gap_p90_m: float
    knock_off_held_max_rad: float
    knock_off_distal_max_rad: float
    knock_off_held_median_rad: float
    knock_off_final_max_rad: float
    trajectory_steps: int
    trajectory_stride: int
    wall_s: float

    def to_dict(self) -> dict:
        d = asdict(self)
        d["false_joints"] = list(self.false_joints)
        return d


def contact_quality(exploration, mesh, false_tol_m: float = FALSE_DETECTION_TOL_M,
                    touch_tol_m: float = TOUCH_TOL_M, trajectory_stride: int | None = None,
                    max_trajectory_configs: int = 2000) -> ContactQuality:
    """Quality figures of a recorded exploration against the true ``mesh`` (closed trimesh,
    world frame, metres), computed after the run.

    Args:
        exploration: an :class:`~explore3d.strategy.explore.Exploration` run with ``record=True``.
        mesh: the true object the exploration ran on.
        false_tol_m: see :data:`FALSE_DETECTION_TOL_M`.
        touch_tol_m: see :data:`TOUCH_TOL_M`.
        trajectory_stride: penetration along trajectories is evaluated every this many steps
            (None: the smallest stride that keeps it to ``max_trajectory_configs`` configurations).
            Detection steps and the touch search of detected sweeps always use every step.
    """
    t0 = time.perf_counter()
    for name, v in (("false_tol_m", false_tol_m), ("touch_tol_m", touch_tol_m)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
            raise ValueError(f"{name} must be a finite distance >= 0 m; got {v!r}")
    atts = [a for w in exploration.attempts for a in w]
    if not atts or any(a.trajectory is None for a in atts):
        raise ValueError("contact_quality needs recorded trajectories; explore with ExploreConfig(record=True)")
    spec = exploration.spec
    n = spec.n_links
    sdf = _as_sdf(mesh)
    dt = float(exploration.config.sim.timestep)

    recs = detection_records(exploration, sdf, touch_tol_m=touch_tol_m, cutoff_m=false_tol_m)
    chain = np.array([r.chain_distance_m for r in recs])
    arm = np.array([r.arm_distance_m for r in recs])
    false = chain > false_tol_m
    free = arm > false_tol_m
    false_joints = np.zeros(n, dtype=int)
    for r, f in zip(recs, false):
        false_joints[r.joint] += int(f)
    delays = np.array([r.delay_steps for r in recs if r.delay_steps >= 0])

    # final configurations: penetration, gaps
    Q = np.array([a.q for a in atts])
    Tb = np.array([a.T_world_base for a in atts])
    C = np.array([a.contact for a in atts])
    Tl = np.einsum("mij,mnjk->mnik", Tb, link_transforms(spec, Q))
    _, _, depth = box_min_distance(spec, Tl.reshape(-1, 4, 4), sdf, cutoff_m=0.0)
    pen = depth.reshape(len(atts), n).max(axis=1)
    gaps, _, _ = contact_gaps(spec, Q, Tb, C, sdf)
    pgaps, _, _ = contact_point_gaps(exploration, sdf)
    # flags in row-major (attempt, joint) order, the order of recs
    true_mask = ~false
    if gaps.size != true_mask.size or pgaps.size != true_mask.size:
        raise ValueError("contact flags and detection records disagree; was the exploration modified?")
    pg = pgaps[true_mask & np.isfinite(pgaps)]

    # trajectories: knock-off (every step), penetration (strided)
    total = int(sum(len(a.trajectory) for a in atts))
    stride = trajectory_stride or max(1, math.ceil(total / max(1, max_trajectory_configs)))
    if not isinstance(stride, int) or stride < 1:
        raise ValueError(f"trajectory_stride must be an integer >= 1; got {trajectory_stride!r}")
    held_max, distal_max, held_per = 0.0, 0.0, []
    pen_traj = 0.0
    for a in atts:
        sw = attempt_swept_joints(a)
        err = np.abs(a.trajectory - a.trajectory_ref)
        j = np.arange(n)[None, :]
        held = np.where(j < sw[:, None], err, 0.0).max(initial=0.0)
        distal = np.where(j > sw[:, None], err, 0.0).max(initial=0.0)
        held_per.append(held)
        held_max, distal_max = max(held_max, held), max(distal_max, distal)
        rows = a.trajectory[::stride]
        Tt = np.einsum("ij,mnjk->mnik", a.T_world_base, link_transforms(spec, rows))
        _, _, dep = box_min_distance(spec, Tt.reshape(-1, 4, 4), sdf, cutoff_m=0.0,
                                  pitches_m=(5.0e-3, TRAJECTORY_PITCH_M))
        pen_traj = max(pen_traj, float(dep.max(initial=0.0)))
    final_knock = float(np.abs(Q - np.array([a.q_ref for a in atts])).max())
    fo = float(exploration.config.face_offset)
    return ContactQuality(
        n_attempts=len(atts), n_detections=len(recs), false_tol_m=float(false_tol_m), n_false=int(false.sum()),
        false_fraction=float(false.mean()) if recs else float("nan"), n_free_space=int(free.sum()),
        free_space_fraction=float(free.mean()) if recs else float("nan"), false_joints=tuple(false_joints.tolist()),
        false_distance_median_m=_q(chain[false], 50), touch_tol_m=float(touch_tol_m), n_delays=int(delays.size),
        delay_median_s=_q(delays, 50) * dt, delay_max_s=float(delays.max()) * dt if delays.size else float("nan"),
        delay_median_steps=_q(delays, 50), delay_max_steps=int(delays.max()) if delays.size else -1,
        penetration_max_m=float(pen.max()), penetration_median_m=_q(pen, 50),
        penetration_trajectory_max_m=max(pen_traj, float(pen.max())),
        gap_median_m=_q(gaps, 50), gap_p90_m=_q(gaps, 90), gap_true_median_m=_q(gaps[true_mask], 50),
        gap_true_p90_m=_q(gaps[true_mask], 90), face_offset_m=fo, point_gap_median_m=_q(pg, 50),
        point_gap_p90_m=_q(pg, 90),
        knock_off_held_max_rad=float(held_max), knock_off_distal_max_rad=float(distal_max),
        knock_off_held_median_rad=_q(held_per, 50), knock_off_final_max_rad=final_knock,
        trajectory_steps=total, trajectory_stride=int(stride), wall_s=time.perf_counter() - t0,
    )


@dataclass(frozen=True)
class FalseDetectionDiagnosis:
    """Why false detections happen, from replays of the wraps with PyBullet's contact report.

    Counts are over the false detections (moving chain farther than ``false_tol_m`` at the
    detection step) of the wraps replayed.

    Attributes:
        n_wraps, n_detections, n_false: sizes.
        n_touched: false detections whose moving chain came within the touch tolerance at any
            step of the sweep (0: the chain never touched: not a spring-back after a contact).
        n_own_lag, n_held, n_distal, n_none: what crossed its band at detection: the swept
            joint's own lag; the error change of a held (proximal) joint; of a not-yet-swept
            (distal) joint; nothing found.
        trigger_joints: (n,) count per triggering joint.
        held_saturated_fraction: of the held-joint triggers, the fraction whose motor applied its
            full torque limit (>= 99%) in the step before the sweep.
        held_error_before_median_rad, held_error_before_max_rad: |q_ref - q| of the triggering
            held joint before the sweep (an error locked in by earlier sweeps).
        trigger_ratio_median: the triggering signal over its band, median.
        held_force_peak_median_n: peak summed normal force on the held links during the sweep, N.
        held_force_drops_fraction: fraction of the sweeps in which the held links' contact force
            dropped to zero at some step while they had been in contact (chatter).
        true_n_own_lag, true_n_held: the same split for the detections that are not false.
    """

    n_wraps: int
    n_detections: int
    n_false: int
    n_touched: int
    n_own_lag: int
    n_held: int
    n_distal: int
    n_none: int
    trigger_joints: tuple
    held_saturated_fraction: float
    held_error_before_median_rad: float
    held_error_before_max_rad: float
    trigger_ratio_median: float
    held_force_peak_median_n: float
    held_force_drops_fraction: float
    true_n_own_lag: int
    true_n_held: int

    def to_dict(self) -> dict:
        d = asdict(self)
        d["trigger_joints"] = list(self.trigger_joints)
        return d


def diagnose_false_detections(exploration, mesh, false_tol_m: float = FALSE_DETECTION_TOL_M,
                              touch_tol_m: float = TOUCH_TOL_M, wraps=None) -> FalseDetectionDiagnosis:
    """Replay ``wraps`` (default all) of a recorded exploration of ``mesh`` (the true closed
    trimesh) and tell what triggered each false detection (see :class:`FalseDetectionDiagnosis`)."""
    sdf = SignedDistance(mesh) if not isinstance(mesh, SignedDistance) else mesh
    spec = exploration.spec
    n = spec.n_links
    wraps = list(range(exploration.n_wraps) if wraps is None else wraps)
    replays = {w: replay_wrap(exploration, sdf.mesh, w) for w in wraps}
    recs = detection_records(exploration, sdf, touch_tol_m=touch_tol_m, cutoff_m=false_tol_m, wraps=wraps,
                             replays=replays)
    trig = np.zeros(n, dtype=int)
    counts = {"own": 0, "held": 0, "distal": 0, "none": 0}
    true_counts = {"own": 0, "held": 0, "distal": 0, "none": 0}
    sat, pre, ratios, peaks, drops = [], [], [], [], []
    n_false = n_touched = 0
    for r in recs:
        kind = "none" if r.trigger < 0 else "own" if r.trigger == r.joint else "held" if r.trigger < r.joint else "distal"
        if r.chain_distance_m <= false_tol_m:
            true_counts[kind] += 1
            continue
        n_false += 1
        n_touched += int(r.touch_row >= 0)
        counts[kind] += 1
        ratios.append(r.trigger_ratio)
        if r.trigger >= 0:
            trig[r.trigger] += 1
        rp = replays[r.wrap]
        idx = np.flatnonzero((rp.attempt == r.attempt) & (rp.sweep_joint == r.joint))
        t0, t1 = int(idx[0]), int(idx[-1])
        F = rp.normal_force_n[t0:t1 + 1, : r.joint].sum(axis=1)
        peaks.append(float(F.max(initial=0.0)))
        drops.append(bool(F.max(initial=0.0) > 0 and (F[np.argmax(F > 0):] == 0).any()))
        if kind == "held":
            j = r.trigger
            sat.append(abs(rp.motor_torque_nm[t0 - 1, j]) >= 0.99 * rp.forces[t0 - 1, j])
            pre.append(abs(rp.q_ref[t0 - 1, j] - rp.q[t0 - 1, j]))
    return FalseDetectionDiagnosis(
        n_wraps=len(wraps), n_detections=len(recs), n_false=n_false, n_touched=n_touched, n_own_lag=counts["own"],
        n_held=counts["held"], n_distal=counts["distal"], n_none=counts["none"], trigger_joints=tuple(trig.tolist()),
        held_saturated_fraction=float(np.mean(sat)) if sat else float("nan"),
        held_error_before_median_rad=_q(pre, 50), held_error_before_max_rad=float(max(pre)) if pre else float("nan"),
        trigger_ratio_median=_q(ratios, 50), held_force_peak_median_n=_q(peaks, 50),
        held_force_drops_fraction=float(np.mean(drops)) if drops else float("nan"),
        true_n_own_lag=true_counts["own"], true_n_held=true_counts["held"])
