"""An exploration read from recorded joint readings alone, with no controller in the loop (issue 26).

A replay (:class:`~explore3d.robot.interface.LogWorkcell`) needs the controller that recorded the
log; another controller's log does not replay.  Here the log is only read: for every motion of
every wrap (one :class:`~explore3d.robot.interface.RobotLog` per wrap):

* **sweeps**: a joint sweeps while its position reference rises from one step to the next (the
  first joint whose reference rose, when several do); a sweep ends when its reference stops
  rising or another joint's starts;
* **detection**: the contact rule of the live controller
  (:class:`~explore3d.feeling.detect.SweepDetector` against the contact ``band``), fed the
  recorded references and angles of the sweep's steps, from the sweep's second step on; at most
  one detection per sweep;
* **settled reading**: after a detection, the first reading at which every joint has stayed
  slower than ``ControlConfig.still_speed`` for ``still_steps`` readings, at least
  ``settle_steps`` after the detection (as :meth:`~explore3d.strategy.encircle.Controller.settle`
  judges it), looked for up to twice ``contact_settle_steps`` readings and never past the next
  sweep's start; none: the last reading looked at, marked not still;
* **contacts**: localised from those readings (:func:`~explore3d.feeling.contacts.localise_attempts`:
  the motor torques, the arm's model, the base pose, gravity);
* **free space**: swept from every recorded reading's angles
  (:func:`~explore3d.reconstruction.freespace.swept_area`).

Times are never read (only the order of the readings), so jittered stamps change nothing, and a
dropped reading shifts the filter by one step.  On explore3d's own logs this finds the moments
the controller found (its detector fed the same numbers) unless the controller ended a sweep for
another reason (its self-contact test; a curl-back's moves read as sweeps).
"""
from __future__ import annotations

import numpy as np

from explore3d.arm.selfcontact import self_contact_pairs
from explore3d.arm.spec import ArmSpec
from explore3d.feeling.contacts import localise_attempts
from explore3d.feeling.detect import ContactBand, SweepDetector
from explore3d.geometry.directions import WrapPose
from explore3d.reconstruction.freespace import swept_area
from explore3d.robot.interface import RobotLog
from explore3d.strategy.encircle import Attempt, ControlConfig, Moment
from explore3d.strategy.explore import Exploration, ExploreConfig, exploration_from_wraps

__all__ = ["band_from_readings", "exploration_from_readings", "motion_moments", "swept_joints"]


def swept_joints(log: RobotLog, first: int, end: int) -> np.ndarray:
    """(end - first,) int: the joint sweeping at each of the rows ``first`` .. ``end`` - 1 of
    ``log`` (one motion): the first whose position reference rose since the row before; -1 for
    none (and for the motion's first row)."""
    q_ref = log.q_ref
    rose = np.zeros((end - first, q_ref.shape[1]), dtype=bool)
    rose[1:] = q_ref[first + 1:end] > q_ref[first:end - 1]
    return np.where(rose.any(axis=1), rose.argmax(axis=1), -1)


def band_from_readings(logs, spec: ArmSpec, control: ControlConfig = ControlConfig(),
                       self_tolerance_m: float | None = None) -> ContactBand:
    """A contact band measured on an arm's own contact-free calibration logs (free motion: every
    joint swept with nothing to touch, e.g. in the orientations of
    :func:`explore3d.world.band.gravity_bounding_bases`): per joint ``control.band_factor`` times
    the largest filtered signal of the live detector (:class:`~explore3d.feeling.detect.SweepDetector`)
    over every sweep step of the logs (module docstring: sweeps are found from the references),
    the swept joint's lag for its own band and every joint's error change for the other band, as
    :func:`explore3d.world.band.calibrate_band` measures the twin's free motion.  Steps at which the
    arm, by its own model, touches itself (within ``self_tolerance_m``, default
    ``control.self_contact_tolerance``) are left out.  A joint that never swept keeps band 0
    (every signal of its sweeps would read as contact): ValueError names it.

    Free motion alone is not the whole calibration: the twin's band also takes the contact-free
    signals of wraps on known objects (impacts shake the other joints), and from free motion alone
    the other-joint bands can be 0 (measured: 0 on the proximal joints of a 16-link arm), which
    would read any error change as a contact.  Pass logs of contact-free wraps beside known
    objects too, or take the twin's band (:func:`explore3d.world.band.cached_band`)."""
    tol = control.self_contact_tolerance if self_tolerance_m is None else float(self_tolerance_m)
    n = spec.n_links
    lag_max, other_max, seen = np.zeros(n), np.zeros(n), np.zeros(n, dtype=int)
    for log in logs:
        if log.spec != spec:
            raise ValueError(f"a calibration log is of the arm {log.spec.name!r}, not {spec.name!r}")
        ends = list(log.start_index[1:]) + [log.n_steps]
        for first, end in zip(log.start_index, ends):
            first, end = int(first), int(end)
            swept = swept_joints(log, first, end)
            det, k_prev = None, -1
            for i in range(1, end - first):
                k = int(swept[i])
                if k < 0:
                    det, k_prev = None, -1
                    continue
                row = first + i
                if k != k_prev:
                    det, k_prev = SweepDetector(k, log.q_ref[row - 1], log.q[row - 1], control.watch_held), k
                lag, sig = det.update(log.q_ref[row - 1][k], log.q_ref[row], log.q[row])
                if self_contact_pairs(spec, log.q[row], tol):
                    continue
                seen[k] += 1
                lag_max[k] = max(lag_max[k], lag)
                np.maximum(other_max, np.abs(sig), out=other_max)
    never = np.flatnonzero(seen == 0)
    if len(never):
        raise ValueError(f"the calibration logs never sweep joint(s) {never.tolist()}: sweep every joint of the arm "
                         "with nothing to touch")
    return ContactBand(swept=control.band_factor * lag_max, other=control.band_factor * other_max,
                       provenance={"rule": "band_factor x the largest contact-free signal of the calibration logs",
                                   "band_factor": control.band_factor, "sweep_steps": seen.tolist()})


def motion_moments(log: RobotLog, first: int, end: int, band: ContactBand,
                   control: ControlConfig = ControlConfig()) -> list[Moment]:
    """The settled readings after each contact detected in the rows ``first`` .. ``end`` - 1 of
    ``log`` (one motion; module docstring).  ``Moment.step`` counts from the motion's start."""
    q_ref, q, dq = log.q_ref, log.q, log.dq
    n = q.shape[1]
    if band.swept.shape != (n,):
        raise ValueError(f"the contact band has {band.swept.shape[0]} joints; the log's arm has {n}")
    swept = swept_joints(log, first, end)
    out = []
    i = 1
    while i < end - first:
        k = int(swept[i])
        if k < 0:
            i += 1
            continue
        r = first + i  # the sweep's first step: the detector starts from the step before it
        det = SweepDetector(k, q_ref[r - 1], q[r - 1], control.watch_held)
        j, hit = i, None
        while j < end - first and swept[j] == k:
            row = first + j
            lag, sig = det.update(q_ref[row - 1][k], q_ref[row], q[row])
            if j > i and SweepDetector.exceeds(band, k, lag, sig):
                hit = j
                break
            j += 1
        if hit is None:
            i = j
            continue
        # the settle: the first still reading after the detection, before the next sweep starts
        run, still, last = 0, False, hit
        limit = min(end - first - 1, hit + 2 * control.contact_settle_steps)
        m = hit + 1
        while m <= limit:
            if m > hit + 1 and swept[m] >= 0 and swept[m] != k:
                break  # the next sweep began
            run = run + 1 if float(np.max(np.abs(dq[first + m]))) <= control.still_speed else 0
            last = m
            if m - hit >= control.settle_steps and run >= control.still_steps:
                still = True
                break
            m += 1
        out.append(Moment(joint=k, step=last, still=still, reading=log.reading(first + last)))
        # the rest of this sweep (the live controller ends it at the detection)
        i = last + 1
        while i < end - first and swept[i] == k:
            i += 1
    return out


def exploration_from_readings(logs, spec: ArmSpec, config: ExploreConfig, band: ContactBand, centre,
                              radius: float, table_z: float | None = None) -> Exploration:
    """The :class:`Exploration` of recorded wraps (one :class:`RobotLog` per wrap, in order) read
    with no controller (module docstring): the contacts it localises and the space it swept,
    chosen for the hull as :func:`~explore3d.strategy.explore.explore_robots` chooses them.

    Args:
        logs: the wraps' logs (their arm must be ``spec``).
        spec: the arm; config: the exploration's settings (its control settings judge the
            settle, its sensing the contacts' uncertainty, its mode and hull settings the rest);
        band: the contact band the logs are read with.
        centre, radius: the rough bound (3,) world frame, m, and m; table_z: the table height
            (world z, m) or None.

    A motion that starts bent (a tip poke, :mod:`explore3d.strategy.poke`; wraps start straight) is
    localised as a poke; its moment is the detection's settled reading (the poke's pressed, averaged
    reading and a contour's readings are the controller's, which a replay reads)."""
    centre = np.asarray(centre, dtype=float)
    results, poses = [], []
    for w, log in enumerate(logs):
        if log.spec != spec:
            raise ValueError(f"log {w} is of the arm {log.spec.name!r}, not {spec.name!r}")
        ends = list(log.start_index[1:]) + [log.n_steps]
        attempts, swept = [], []
        for mi, (first, end) in enumerate(zip(log.start_index, ends)):
            first, end = int(first), int(end)
            T = np.asarray(log.base_T[mi], dtype=float)
            moments = motion_moments(log, first, end, band, config.control)
            contact = np.zeros(spec.n_links, dtype=bool)
            contact[[m.joint for m in moments]] = True
            attempts.append(Attempt(T_world_base=T, q=log.q[end - 1].copy(), q_ref=log.q_ref[end - 1].copy(),
                                    contact=contact, reasons=(), detect_step=np.zeros(spec.n_links, dtype=int),
                                    steps=end - first - 1, moments=tuple(moments),
                                    poke=bool(np.any(np.asarray(log.start_q[mi]) != 0))))
            if config.free_space:
                swept.append(swept_area(spec, log.q[first:end], T, centre, radius))
        contacts = localise_attempts(spec, attempts, np.asarray(log.gravity, float), config.sensors, wrap=w)
        results.append((attempts, log.n_steps - len(log.start_index), None, contacts, swept))
        T0 = np.asarray(log.base_T[0], dtype=float)
        normal = T0[:3, 2]
        poses.append(WrapPose(T0, normal, float((T0[:3, 3] - centre) @ normal), 0.0, f"log {w}"))
    return exploration_from_wraps(spec, config, band, centre, radius, poses, results, table_z)
