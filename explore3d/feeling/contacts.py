"""Contacts localised from proprioception over an exploration: where on which link the arm
touched, with the force, the normal and the uncertainty (pure numpy on the robot's readings).

Every detected contact of an attempt ends with a settled reading (:class:`explore3d.strategy.encircle.Moment`:
joint angles and motor torques once the arm is still).  :func:`localise_moment` turns one into
contacts with :func:`explore3d.feeling.localise.localise`; :func:`localise_attempts` does every moment of
an exploration and gathers them into a :class:`ContactSet`, marking those that lie on the arm
itself (a curled chain touching itself, :mod:`explore3d.arm.selfcontact`); :func:`contacts_for_hull`
chooses the certain ones on the object and, in 3D, their height across the link
(:func:`resolve_heights`).  Nothing here
reads the simulator:
only the readings, the arm's model, the known base pose, gravity and the sensing's datasheet
figures (its torque noise and resolution, its encoder's counts).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import trimesh

from explore3d.arm.kinematics import link_transforms
from explore3d.arm.selfcontact import near_other_body
from explore3d.arm.spec import ArmSpec
from explore3d.feeling.localise import CHI2_GAIN, TIP_EXTRA, Localisation, external_torques, localise
from explore3d.reconstruction.hull_input import reconstruct_points
from explore3d.robot.sensing import SensorConfig

__all__ = ["ContactSet", "localise_moment", "localise_attempts", "on_the_arm", "torque_sigma_nm", "position_sigma_m",
           "contact_uncertainty_m", "resolve_heights", "contacts_for_hull", "MODEL_TORQUE_SIGMA_NM",
           "MAX_UNCERTAINTY_M", "MAX_RESIDUAL_SIGMAS", "JUDGE_A"]

#: The smallest torque uncertainty a fit assumes, N m: the model's own error at a settled
#: moment (PyBullet's unmodelled joint damping and the residual motion left 1e-5 to 6e-5 N m
#: median between the static model and exact torques; BENCHMARKS.md, localisation section).
MODEL_TORQUE_SIGMA_NM = 2.0e-4


def torque_sigma_nm(sensors: SensorConfig, readings: int = 1) -> float:
    """1-sigma uncertainty of one external joint torque, N m: the current sensor's noise and its
    quantisation (``resolution / sqrt(12)``; the noise dithers it), over ``sqrt(readings)`` for the
    mean of that many readings, at least :data:`MODEL_TORQUE_SIGMA_NM` (the model's own error,
    which averaging does not remove)."""
    s = math.hypot(sensors.torque_noise_nm, sensors.torque_resolution_nm / math.sqrt(12.0))
    return max(s / math.sqrt(max(1, int(readings))), MODEL_TORQUE_SIGMA_NM)


def position_sigma_m(spec: ArmSpec, sensors: SensorConfig) -> float:
    """Model error of the modelled link positions from the encoders, metres: one count's
    quantisation error (``resolution / sqrt(12)``) times the arm's reach (a joint's angle error
    moves every point beyond it by at most that lever).  0 for exact angles."""
    return sensors.angle_resolution_rad / math.sqrt(12.0) * spec.n_links * spec.link_length


@dataclass(frozen=True)
class ContactSet:
    """Localised contacts (m of them), world frame, SI units.

    Attributes:
        points: (m, 3) contact points at the link's mid-height (the height across the link is
            unobservable from a planar chain's joint torques), metres.
        segments: (m, 2, 3) the link face across its height at the located position, metres
            (the contact lies on it; every point of it is outside the object).
        normals: (m, 3) unit contact normals (the force on the link, pointing into it).
        force_n: (m,) contact force, N.
        sigma_along_m: (m,) 1-sigma position uncertainty along the link's outline, metres.
        along_interval_m: (m, 2) the positions along the link (x in its frame, metres) at which one
            contact explains the torques as well (the profile interval).
        link, wrap, attempt, joint: (m,) int: the link touched; the wrap, attempt and the swept
            joint whose settled reading located it.
        kind: (m,) str: the candidate kind (a face or a corner, :data:`explore3d.feeling.localise.KINDS`).
        still: (m,) bool: the reading was taken with the arm still (False: the settle ran out).
        residual_nm: (m,) RMS torque residual of the fit of the contact's reading, N m.
        uncertainty_m: (m,) position uncertainty along the link, metres
            (:func:`contact_uncertainty_m`; NaN until :func:`contacts_for_hull` sets it).
        used: (m,) bool: the contact is in the hull input (:func:`contacts_for_hull`: its
            uncertainty is within the bound; all False until then).
        self_contact: (m,) bool: the arm touching itself, not the object: by the arm's model at
            the reading's angles the contact (its point or its profile interval) lies within
            :data:`~explore3d.arm.selfcontact.SELF_CONTACT_TOLERANCE_M` of a body of the arm other than
            its link and the two adjacent to it (:func:`on_the_arm`).  Never used for the hull.
        sigma_nm: (m,) the torque uncertainty of the contact's reading, N m (:func:`torque_sigma_nm`
            for the mean of its readings; NaN: not known, the sensing's single reading applies).
    """

    points: np.ndarray
    segments: np.ndarray
    normals: np.ndarray
    force_n: np.ndarray
    sigma_along_m: np.ndarray
    along_interval_m: np.ndarray
    link: np.ndarray
    wrap: np.ndarray
    attempt: np.ndarray
    joint: np.ndarray
    kind: np.ndarray
    still: np.ndarray
    residual_nm: np.ndarray = None
    uncertainty_m: np.ndarray = None
    used: np.ndarray = None
    self_contact: np.ndarray = None
    sigma_nm: np.ndarray = None

    def __post_init__(self):
        m = len(self.points)
        if self.residual_nm is None:
            object.__setattr__(self, "residual_nm", np.full(m, np.nan))
        if self.uncertainty_m is None:
            object.__setattr__(self, "uncertainty_m", np.full(m, np.nan))
        if self.used is None:
            object.__setattr__(self, "used", np.zeros(m, dtype=bool))
        if self.self_contact is None:
            object.__setattr__(self, "self_contact", np.zeros(m, dtype=bool))
        if self.sigma_nm is None:
            object.__setattr__(self, "sigma_nm", np.full(m, np.nan))

    def __len__(self) -> int:
        return len(self.points)

    @classmethod
    def empty(cls) -> "ContactSet":
        z = np.zeros(0, dtype=int)
        return cls(np.zeros((0, 3)), np.zeros((0, 2, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0),
                   np.zeros((0, 2)), z, z, z, z, np.zeros(0, dtype="<U16"), np.zeros(0, dtype=bool),
                   np.zeros(0), np.zeros(0), np.zeros(0, dtype=bool), np.zeros(0, dtype=bool), np.zeros(0))

    @classmethod
    def concatenate(cls, sets) -> "ContactSet":
        sets = list(sets)
        if not sets:
            return cls.empty()
        return cls(*(np.concatenate([getattr(s, f) for s in sets]) for f in cls.__dataclass_fields__))

    def select(self, mask) -> "ContactSet":
        """The contacts where ``mask`` (m,) bool or an index array."""
        return ContactSet(*(getattr(self, f)[mask] for f in self.__dataclass_fields__))


def localise_moment(spec: ArmSpec, moment, T_world_base, gravity, sensors: SensorConfig,
                    poke: bool = False) -> Localisation:
    """The contacts at one settled reading (:class:`explore3d.strategy.encircle.Moment`), base pose
    ``T_world_base`` (4, 4), ``gravity`` (3,) m/s^2 (world), with the sensing's uncertainties.

    ``poke``: the reading of a tip poke (:mod:`explore3d.strategy.poke`), whose tip leads and whose
    other links trail behind it.  A force along the tip link passes through the tip's own joint, so
    the torques cannot tell a touch on the tip's distal face from one on the inner corner of the
    link before it, on the same line 20 mm back (measured: 3 of 51 readings of a tip sliding on a
    cube's face were placed there, 18 mm off the face).  When the tip alone explains the torques
    as well (within the significance threshold ``chi2_gain * sigma^2`` of the best fit), the tip it is.
    """
    r = moment.reading
    tau_ext = external_torques(spec, r.q, r.tau, T_world_base, gravity)
    kw = dict(sigma_nm=torque_sigma_nm(sensors, moment.readings), position_sigma_m=position_sigma_m(spec, sensors))
    loc = localise(spec, r.q, tau_ext, T_world_base, **kw)
    tip = spec.n_links - 1
    if poke and loc.contacts and all(c.link != tip for c in loc.contacts):
        alt = localise(spec, r.q, tau_ext, T_world_base, links=(tip,), **kw)
        if alt.contacts and alt.rss <= loc.rss + CHI2_GAIN * kw["sigma_nm"] ** 2:
            loc = alt
    if poke:  # the tip's distal face lies at x = L: that is its profile interval
        loc = dataclasses.replace(loc, contacts=tuple(
            dataclasses.replace(c, along_interval_m=(spec.link_length, spec.link_length))
            if c.link == tip and c.kind in TIP_EXTRA else c for c in loc.contacts))
    return loc


#: Points sampled along a contact's profile interval when testing it against the arm's other bodies.
SELF_CONTACT_SAMPLES = 9


def on_the_arm(spec: ArmSpec, q, T_world_base, contacts) -> np.ndarray:
    """(m,) bool: each localised contact (:class:`~explore3d.feeling.localise.LocalContact`, at joint angles
    ``q`` (n,), rad, base pose ``T_world_base`` (4, 4)) may be the arm touching itself: its point,
    or a point of its inner face anywhere in its profile interval (the positions along the link
    that explain the torques as well, :attr:`~explore3d.feeling.localise.LocalContact.along_interval_m`),
    lies within :data:`~explore3d.arm.selfcontact.SELF_CONTACT_TOLERANCE_M` of a body of the arm
    other than its link and the two adjacent to it.  The interval matters: with the torques of
    only the joints up to the touched link, a face point and a corner fit alike, and the located
    point may lie millimetres from where the other body touches."""
    T = link_transforms(spec, q, T_world_base)
    w = spec.link_width / 2
    points, links, owner = [], [], []
    for i, c in enumerate(contacts):
        pts = [np.asarray(c.point_link, float)]
        lo, hi = c.along_interval_m
        if np.isfinite(lo) and np.isfinite(hi):
            pts += [np.array([x, w, 0.0]) for x in np.linspace(lo, hi, SELF_CONTACT_SAMPLES)]
        Tl = T[c.link]
        points += [Tl[:3, :3] @ p + Tl[:3, 3] for p in pts]
        links += [c.link] * len(pts)
        owner += [i] * len(pts)
    out = np.zeros(len(contacts), dtype=bool)
    if points:
        np.logical_or.at(out, np.array(owner), near_other_body(spec, q, links, points, T_world_base))
    return out


def localise_attempts(spec: ArmSpec, attempts, gravity, sensors: SensorConfig, wrap: int = 0) -> ContactSet:
    """Localise every moment of one wrap's ``attempts`` (see :func:`localise_moment`); ``wrap``
    labels them.  Contacts that lie on the arm itself are marked (:attr:`ContactSet.self_contact`).

    A tip poke's moments (an attempt with ``poke`` set) are localised as such
    (:func:`localise_moment`): a contact on the tip's distal face or its outer distal corner lies
    at the link's distal end, x = L, its profile interval that point.  The hook puts the joints
    off the force's line, so the torques place it (across the face, to the fit's sigma); on a
    straight chain they cannot, and such contacts keep no interval (infinitely uncertain,
    :func:`contact_uncertainty_m`)."""
    rows = []
    for ai, att in enumerate(attempts):
        for m in att.moments:
            loc = localise_moment(spec, m, att.T_world_base, gravity, sensors, poke=getattr(att, "poke", False))
            if not loc.contacts:
                continue
            on_arm = on_the_arm(spec, m.reading.q, att.T_world_base, loc.contacts)
            for c, s in zip(loc.contacts, on_arm):
                rows.append((c, ai, m, loc.residual_nm, bool(s), loc.sigma_nm))
    if not rows:
        return ContactSet.empty()
    cs = [r[0] for r in rows]
    return ContactSet(
        points=np.array([c.point_world for c in cs], float),
        segments=np.array([c.segment_world for c in cs], float),
        normals=np.array([c.normal_world for c in cs], float),
        force_n=np.array([c.force_n for c in cs], float),
        sigma_along_m=np.array([c.sigma_along_m for c in cs], float),
        along_interval_m=np.array([c.along_interval_m for c in cs], float).reshape(-1, 2),
        link=np.array([c.link for c in cs], int),
        wrap=np.full(len(cs), wrap, int),
        attempt=np.array([r[1] for r in rows], int),
        joint=np.array([r[2].joint for r in rows], int),
        kind=np.array([c.kind for c in cs], dtype="<U16"),
        still=np.array([r[2].still for r in rows], bool),
        residual_nm=np.array([r[3] for r in rows], float),
        self_contact=np.array([r[4] for r in rows], bool),
        sigma_nm=np.array([r[5] for r in rows], float),
    )


#: Largest position uncertainty along the link, metres, of a contact the hull is built from
#: (:func:`contact_uncertainty_m`).  The hull follows its outermost points, so a contact placed
#: wrongly outward costs more than one left out: half the localisation target of 1 mm.  Measured
#: on the six convex built-ins (default 3D runs): 0.5 mm gave 4.8% mean volume error, 1 mm 6.2%
#: (the cone 10.4% against 18.9%); BENCHMARKS.md.
MAX_UNCERTAINTY_M = 0.5e-3

#: A reading's contacts are used only if their fit explains it: RMS torque residual at most this
#: many torque sigmas.  Over n joints the RMS of pure noise is sigma (1 +- 1/sqrt(2n)): 0.14 sigma
#: for the 24-joint default arm, so 2 sigma is far beyond chance; a larger residual is torque the
#: model did not explain (unmodelled motion, a contact it missed), and the contacts fitted beside
#: it are suspect (measured on the default box run: residual 1.1 mN m median for contacts within
#: 2 mm of the surface, 5.2 mN m for those farther; BENCHMARKS.md).
MAX_RESIDUAL_SIGMAS = 2.0


def contact_uncertainty_m(cs: ContactSet, sigma_nm) -> np.ndarray:
    """(m,) position uncertainty of each contact along its link, metres: the largest of

    * the reading's resolution ``sigma_nm / force``: a force F moved by d along the link changes
      every proximal joint torque by F d, so one torque sigma hides d = sigma / F;
    * the width of the profile interval (:attr:`ContactSet.along_interval_m`: where one contact
      explains the torques as well; wide where the geometry is degenerate): the contact may be
      anywhere in it, so its width is the worst-case error of the reported point;
    * the fit's own 1-sigma (:attr:`ContactSet.sigma_along_m`).

    Contacts without a profile interval (the tip's distal face) count as infinitely uncertain.
    """
    with np.errstate(divide="ignore"):
        res = np.where(cs.force_n > 0, sigma_nm / np.maximum(cs.force_n, 1e-300), np.inf)
    width = cs.along_interval_m[:, 1] - cs.along_interval_m[:, 0]
    width = np.where(np.isfinite(width), width, np.inf)
    return np.maximum(np.maximum(res, width), cs.sigma_along_m)


#: The coarseness of the hulls that judge the heights (:func:`resolve_heights`): tighter than the
#: reconstruction's default, so the judge follows the contacts closely.
JUDGE_A = 0.02


def resolve_heights(segments, wrap, centre, radius: float, group=None, iterations: int = 6, samples: int = 11,
                    a: float = JUDGE_A) -> np.ndarray:
    """Where across the link's height each contact lies, from the contacts of the other wraps.

    A planar chain's joint torques do not see the height of a contact across a link: it lies
    somewhere on its face segment (every point of which is outside the object).  The touching
    point is the segment's point deepest inside the object.  So: start from the mid-height points;
    split the wrap planes into two folds (``group`` parity); build the inverse hull of one fold's
    points (:func:`explore3d.reconstruction.hull_input.reconstruct_points`) and move each contact of the other fold
    to the sample of its segment deepest inside (or least outside) it, and the other way round;
    repeat ``iterations`` times.  A contact is never judged by its own plane's points: they share
    its blindness to height (measured on the 80 mm cube's default run: 5.6% volume error judged
    against every contact, 3.1% against the other fold).  Ties (a segment lying along the
    estimate's surface) go to the sample nearest mid-height.  Measured on the six convex built-ins
    (default 3D runs; BENCHMARKS.md), mean volume error: mid-height points 13.0%, this with 3
    iterations and the reconstruction's coarseness 0.05 4.8%, with 6 iterations and
    :data:`JUDGE_A` 4.4% (the true heights: 3.3%).

    Args:
        segments: (m, 2, 3) face segments, world frame, metres.
        wrap: (m,) int wrap ids (for the hull's outlier filter).
        centre: (3,) rough centre, metres; radius: rough bounding radius, metres.
        group: (m,) int: the wrap plane of each contact (None: the wrap id).
        iterations: estimate/choose rounds; samples: points per segment.
        a: the judging hulls' coarseness (:data:`JUDGE_A`).

    Returns:
        (m, 3) the chosen points, world frame, metres (mid-height where a fold gave no hull).
    """
    S = np.asarray(segments, dtype=float)
    wrap = np.asarray(wrap)
    group = wrap if group is None else np.asarray(group)
    t = np.linspace(0.0, 1.0, samples)
    cand = S[:, :1, :] * (1.0 - t[None, :, None]) + S[:, 1:, :] * t[None, :, None]  # (m, samples, 3)
    mid_rank = np.abs(t - 0.5)[None, :]
    P = S.mean(axis=1)
    fold = group % 2
    for _ in range(iterations):
        new = P.copy()
        for f in (0, 1):
            judge, judged = fold != f, fold == f
            if judge.sum() < 4 or not judged.any():
                continue
            try:
                est = reconstruct_points(P[judge], wrap[judge], centre, radius, a=a).shape()
            except ValueError:
                continue
            C = cand[judged]
            sd = trimesh.proximity.signed_distance(est, C.reshape(-1, 3)).reshape(len(C), samples)  # + inside
            near_best = sd >= sd.max(axis=1, keepdims=True) - 1.0e-5
            pick = np.argmin(np.where(near_best, mid_rank, np.inf), axis=1)
            new[judged] = C[np.arange(len(C)), pick]
        P = new
    return P


def contacts_for_hull(cs: ContactSet, config, centre, radius: float, plane=None,
                      max_uncertainty_m: float = MAX_UNCERTAINTY_M) -> ContactSet:
    """The contacts with their uncertainty set and the hull input chosen: ``used`` marks those
    within ``max_uncertainty_m`` metres (:func:`contact_uncertainty_m` with the sensing of
    ``config``, an :class:`~explore3d.strategy.explore.ExploreConfig`) from still readings (the static
    model holds; measured on the default 3D runs of the box and the cube, 10 of the 13 contacts
    placed more than 3 mm off came from readings whose settle ran out) that their fit explains
    (:data:`MAX_RESIDUAL_SIGMAS`) and that are not the arm touching itself
    (:attr:`ContactSet.self_contact`); in 3D their ``points`` are moved
    across the link's height by :func:`resolve_heights` (planar: the mid-height points, the
    plane's section).  The rough ``centre`` (3,) and ``radius`` (m) bound the estimate;
    ``plane`` (n_wraps,) int gives each wrap's plane (None: a plane per wrap)."""
    sigma = np.where(np.isfinite(cs.sigma_nm), cs.sigma_nm, torque_sigma_nm(config.sensors))
    u = contact_uncertainty_m(cs, sigma)
    used = (u <= max_uncertainty_m) & (cs.residual_nm <= MAX_RESIDUAL_SIGMAS * sigma) & cs.still & ~cs.self_contact
    points = cs.points.copy()
    if config.mode != "planar" and used.any():
        group = None if plane is None else np.asarray(plane)[cs.wrap[used]]
        points[used] = resolve_heights(cs.segments[used], cs.wrap[used], centre, radius, group=group)
    return dataclasses.replace(cs, points=points, uncertainty_m=u, used=used)
