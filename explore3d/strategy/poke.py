"""Tip probing (issue 24, item 2): the tip brought along the estimate's inward normal onto a target.

A straight chain cannot feel a force along itself: each joint sees the force times its distance
from the force's line, and every joint lies on it.  A *hook* bends the distal links (the last
:data:`HOOK_JOINTS` joints, evenly) so that the tip link lies across the radius from the base joint
to the tip (:func:`hook_angles`): turning the base joint then moves the tip along its own axis,
and a force on the tip's distal face has the whole reach (0.45 m for the default arm) as its
lever about the base joint -- the base joint's sweep detects it by its lag, as any touch -- and
one link length times the sine of the bend (10 mm at the default arm's 32 degrees) about the joint
before the tip.  How far from straight is enough: at the default sensing a joint's torque is
significant from five standard deviations, 5 mN m for one reading and 1 mN m for the mean of
:data:`POKE_AVERAGE_STEPS` (the model's floor), so at the :data:`POKE_FORCE_N` press the tip's axis
must pass at least 13 mm (one reading) or 2.6 mm (the mean) from a joint for that joint to see
the touch: a bend of 8 degrees at the joint before the tip, with the mean.  The torques place the
force's line across the tip's face to the noise over the force; along the line the touch is on
the tip's distal face (:func:`explore3d.feeling.localise.localise` adds it to its candidates) --
or on the inner corner of the link before it, on the same line through the tip's joint, which no
bend separates (:func:`explore3d.feeling.contacts.localise_moment` takes the tip, which leads).

A poke (:func:`poke_poses`, :func:`run_poke`): for a target on the estimate's surface with outward
normal ``n``, a plane containing ``n``; the base placed so the tip, turning about the base joint,
passes the target moving along ``-n``; the arm starting in the hook 10, 20 or 40 mm before the
target (by the arc: the nearest whose start the estimate leaves empty); the base joint sweeping
towards the target and on, ``depth`` beyond it (the volume at stake there: the estimate may bridge
a fold that deep), until the detector fires; the touch then settled and read as a wrap's touch
is, pressed on until it can be placed.  Of the planes about ``n`` the one is taken whose arm, with
the tip at the target, keeps clearest of the estimate (the tip link aside); a target where every
plane's arm would start inside the estimate (outside the space the wraps swept, proven empty),
or the base inside the rough bound, gets no poke.  Pure geometry on what the robot believes (its
model, the estimate, the rough bound); the motion sees the
:class:`~explore3d.robot.interface.Robot` only.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from explore3d.arm.kinematics import link_frames_planar, link_transforms
from explore3d.arm.spec import ArmSpec
from explore3d.feeling.detect import ContactBand
from explore3d.geometry.directions import WrapPose, frame_from_normal
from explore3d.robot.interface import Robot
from explore3d.strategy.encircle import (
    Attempt,
    ControlConfig,
    Controller,
    Moment,
    StopReason,
    carried_force,
    settle_touch,
    sweep_joint,
    sweep_speeds,
    sweep_torque_limits,
)

__all__ = ["HOOK_JOINTS", "PokePose", "hook_angles", "tip_point", "poke_frame", "poke_poses", "run_poke",
           "arm_points"]

#: Distal joints bent into the hook (evenly).  Three joints of the default arm bend 30 degrees each
#: (plus the small tilt that makes the tip move along itself): the joint before the tip then has
#: a 10 mm lever on a force along the tip (module docstring).
HOOK_JOINTS = 3

#: A poke's touch is read once the tip presses at least this hard, N (by the arm's model,
#: :func:`~explore3d.strategy.encircle.carried_force`): the detection's settle often leaves the tip
#: resting with a force too small to place (measured on a cube's faces from 36 arm planes: 24 placed
#: within 1 mm; pressing with the sweep's whole torque limit instead set 10 of 36 chattering end-on).
POKE_FORCE_N = 0.4

#: A poke's moment is the mean of this many still readings (at least; more if
#: :attr:`~explore3d.strategy.encircle.ControlConfig.average_steps` says so): a reading places a touch
#: across the tip's face to the torque noise over the force, 1 mN m / 0.9 N = 1.2 mm at the sweep's
#: torque limit over the hook's 0.45 m radius, and the hull takes contacts placed within 0.5 mm; the
#: mean of 25 brings the noise to 0.2 mN m (the model's own floor), 0.23 mm.  Pressing harder
#: instead (2.5 N) left 8 of 36 pokes on a cube's faces unsettled.
POKE_AVERAGE_STEPS = 25

#: Below :data:`POKE_FORCE_N` the base joint's reference creeps on by this much more at the tip each
#: time, m, and the touch settles again, at most :data:`POKE_PRESS_STEPS` times (measured as above:
#: 35 of 36 placed within 1 mm, still).
POKE_CREEP_M = 0.001
POKE_PRESS_STEPS = 6

#: Contour following (:func:`slide_tip`): the tip's end moves this far across the surface between
#: readings, m.
SLIDE_STEP_M = 0.003

#: The tip's speed along its axis while it pokes, m/s (the wraps' links sweep at up to
#: :attr:`~explore3d.strategy.encircle.ControlConfig.tip_speed`, 0.3 m/s): end-on, the chain does not bend
#: as it does under a side touch, and a fast tip bounces off a face (measured below).
POKE_TIP_SPEED_M_S = 0.05


@dataclass(frozen=True)
class PokePose(WrapPose):
    """A poke's base pose and motion (see :class:`~explore3d.geometry.directions.WrapPose` for
    ``T_world_base``, ``normal`` (the arm's plane), ``offset``, ``angle``, ``label``).

    Attributes:
        q0: (n,) the hook the arm starts in, rad (:func:`hook_angles`).
        stop_rad: the base joint's stop angle, rad: the tip as far past the target as its depth.
        target: (3,) the target point, world frame, m.
    """

    q0: np.ndarray | None = None
    stop_rad: float = 0.0
    target: np.ndarray | None = None


def tip_point(spec: ArmSpec, q) -> tuple[np.ndarray, float]:
    """The tip link's distal face centre (2,), base x-y plane, m, and the tip link's heading, rad,
    at joint angles ``q`` (n,)."""
    origins, headings = link_frames_planar(spec, np.asarray(q, float))
    h = float(headings[-1])
    return origins[-1] + spec.link_length * np.array([math.cos(h), math.sin(h)]), h


def hook_angles(spec: ArmSpec, joints: int = HOOK_JOINTS, tilt_rad: float = 0.0) -> np.ndarray:
    """(n,) joint angles, rad: the base joint and the proximal chain straight, the last ``joints``
    joints bent evenly towards +y so that the tip link lies across the radius from the base joint
    to the tip (it moves along its own axis, distal face first, as the base joint turns: its
    heading is the tip's polar angle plus 90 degrees; solved by fixed-point iteration)."""
    n = spec.n_links
    if not (isinstance(joints, int) and 2 <= joints <= n - 1):
        raise ValueError(f"hook joints must be an integer in [2, {n - 1}] (the arm has {n} joints); got {joints!r}")
    q = np.zeros(n)
    total = math.pi / 2
    for _ in range(50):
        q[n - joints:] = total / joints
        p, _ = tip_point(spec, q)
        new = math.pi / 2 + math.atan2(p[1], p[0]) + tilt_rad
        if abs(new - total) < 1e-12:
            break
        total = new
    if total / joints > spec.joint_upper:
        raise ValueError(f"the hook bends each of its {joints} joints {total / joints:.3f} rad, past the joint limit "
                         f"{spec.joint_upper:.3f} rad: use more hook joints")
    return q


def poke_frame(spec: ArmSpec, q0, target, normal, plane_normal, before_m: float) -> np.ndarray:
    """(4, 4) ``T_world_base`` of a poke: the arm's plane has unit normal ``plane_normal`` (3,),
    perpendicular to the target's outward unit ``normal`` (3,); with the arm in ``q0`` (n,) rad
    (:func:`hook_angles`) and the base joint turned by ``before_m`` over the tip's radius, the tip
    is at ``target`` (3,), world frame, m, moving along ``-normal``.  At base angle 0 the tip is
    ``before_m`` back along its arc."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    z = np.asarray(plane_normal, float) / np.linalg.norm(plane_normal)
    p, _ = tip_point(spec, q0)
    R = float(np.linalg.norm(p))
    d = np.cross(z, n)  # from the base joint to the tip when the tip moves along -n
    theta = -(math.atan2(p[1], p[0]) + before_m / R)  # turn d back to the base's x axis
    x = math.cos(theta) * d + math.sin(theta) * np.cross(z, d)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, np.cross(z, x), z], axis=1)
    T[:3, 3] = np.asarray(target, float) - R * d
    return T


def arm_points(spec: ArmSpec, q, T_world_base, gap_m: float = 0.0, step_m: float = 0.004) -> np.ndarray:
    """(n, k, 3) points on and around each link at joint angles ``q`` (n,) rad, world frame, m:
    its axis every ``step_m`` from joint to distal end, at the centre and the corners of its cross
    section grown by ``gap_m`` all round."""
    xs = np.linspace(0.0, spec.link_length, max(2, int(math.ceil(spec.link_length / step_m)) + 1))
    hw, hh = spec.link_width / 2 + gap_m, spec.link_height / 2 + gap_m
    yz = [(a, b) for a in (-hw, 0.0, hw) for b in (-hh, 0.0, hh)]
    local = np.array([[x, a, b, 1.0] for x in xs for a, b in yz])  # (k, 4)
    T = link_transforms(spec, np.asarray(q, float), T_world_base)  # (n, 4, 4)
    return np.einsum("nij,kj->nki", T, local)[..., :3]


def poke_poses(targets, normals, depths, estimate, centre, radius: float, spec: ArmSpec,
               joints: int = HOOK_JOINTS, standoffs=(0.01, 0.02, 0.04), gap_m: float = 0.003, planes: int = 12,
               floor_z: float | None = None, free=None, label: str = "poke") -> list[PokePose]:
    """One poke per target (module docstring) where one fits.

    Args:
        targets: (t, 3) points on the estimate, world frame, m.
        normals: (t, 3) their outward unit normals.
        depths: (t,) how far past each target the tip may go, m (the volume at stake there).
        estimate: the estimate (closed trimesh, m).
        centre, radius: the rough bound (3,), m: the base joint stays outside it.
        joints: hook joints (:func:`hook_angles`).
        standoffs: the tip starts this far before the target along its arc, m: the first of these
            at which the arm's start (its cross section grown by ``gap_m`` all round) lies outside
            the estimate (or in ``free``).  The path from there is the probe: it may cross the
            estimate, which holds more than the object.
        gap_m: clearance kept from the estimate by the arm's cross section at the start.
        planes: arm planes tried, evenly about each normal (both hook sides).  Of the feasible
            ones the one with the shortest standoff is taken, then the one whose arm with the tip at
            the target has the fewest points inside the estimate (the tip link aside), then the
            farthest from its surface, then the first.
        floor_z: a table's height plus its clearance, world z, m: no point of the arm below it, at
            the start or with the tip at its deepest (None: no table).
        free: ``free(points (m, 3)) -> (m,) bool``, space the wraps swept through (proven empty;
            :func:`explore3d.reconstruction.freespace.is_free`): the arm may start there though the
            estimate holds it (the estimate's creases, carved narrower than the tip's clear section,
            otherwise keep every poke out).  None: outside the estimate only.

    Returns:
        :class:`PokePose` list, in target order.
    """
    centre = np.asarray(centre, float)
    q0 = hook_angles(spec, joints)
    R = float(np.linalg.norm(tip_point(spec, q0)[0]))
    S, _ = trimesh.sample.sample_surface(estimate, 4000, seed=0)
    near = cKDTree(S)
    out = []
    for ti, (p, nv, dep) in enumerate(zip(np.asarray(targets, float), np.asarray(normals, float),
                                          np.asarray(depths, float))):
        u, v, nv = frame_from_normal(nv).T  # nv normalised; u, v span its tangent plane
        best = None
        for j in range(planes):
            a = 2 * math.pi * j / planes
            z = math.cos(a) * u + math.sin(a) * v
            for before in standoffs:
                T = poke_frame(spec, q0, p, nv, z, before)
                if np.linalg.norm(T[:3, 3] - centre) <= radius:
                    break
                stop = (before + float(dep)) / R
                start = arm_points(spec, q0, T, gap_m).reshape(-1, 3)
                if floor_z is not None:
                    q_end = q0.copy()
                    q_end[0] = stop
                    if min(start[:, 2].min(), arm_points(spec, q_end, T, gap_m)[..., 2].min()) < floor_z:
                        break
                inside = estimate.contains(start)
                if inside.any() and (free is None or not free(start[inside]).all()):
                    continue  # start farther back
                q_at = q0.copy()
                q_at[0] = before / R
                at = arm_points(spec, q_at, T, gap_m)[:-1].reshape(-1, 3)  # the tip link aside
                key = (before, int(estimate.contains(at).sum()), -float(near.query(at)[0].min()), j)
                if best is None or key < best[0]:
                    best = (key, T, z, stop, j)
                break
        if best is not None:
            _, T, z, stop, j = best
            out.append(PokePose(T, z, float((T[:3, 3] - centre) @ z), 2 * math.pi * j / planes,
                                f"{label} t{ti} p{j}", q0=q0.copy(), stop_rad=float(stop), target=p.copy()))
    return out


def slide_tip(ctl: Controller, q_ref: np.ndarray, push_nm: float, radius_m: float, steps: int,
              step_m: float = SLIDE_STEP_M) -> list:
    """Contour following with the tip (issue 24, item 3), after a poke's touch: the base joint keeps
    pushing the tip onto the surface with its torque limit ``push_nm`` N m (its reference
    :data:`POKE_CREEP_M` ahead of where it stands, over the hook's radius ``radius_m``), and the tip
    joint turns so the tip's end slides across the surface, ``step_m`` at a time (its angle over
    the link length), ``steps`` steps one way, back, and ``steps`` the other way; after each step the
    arm settles and a moment is read (the mean of :data:`POKE_AVERAGE_STEPS` still readings).  A
    direction ends early when the arm does not settle or the tip no longer presses with
    :data:`POKE_FORCE_N` (it slid off an edge).  ``q_ref`` (n,) rad changes in place.  Returns the
    :class:`~explore3d.strategy.encircle.Moment` list, each localised like any touch."""
    spec, cfg = ctl.spec, ctl.cfg
    j = spec.n_links - 1
    limits = ctl.full.copy()
    limits[0] = push_nm
    centre = float(q_ref[j])
    out = []

    def go(angle):  # turn the tip joint there on a short ramp, pushing all the while
        a0 = float(q_ref[j])
        n_ramp = max(1, int(math.ceil(abs(angle - a0) * spec.link_length / (POKE_TIP_SPEED_M_S * ctl.robot.dt))))
        for i in range(1, n_ramp + 1):
            q_ref[j] = a0 + (angle - a0) * i / n_ramp
            q_ref[0] = ctl.reading.q[0] + POKE_CREEP_M / radius_m
            ctl.send(q_ref, None, limits)
        q_ref[0] = ctl.reading.q[0] + POKE_CREEP_M / radius_m
        return ctl.settle(q_ref, limits)[0]

    for sign in (1.0, -1.0):
        for i in range(1, steps + 1):
            angle = centre + sign * i * step_m / spec.link_length
            if not spec.joint_lower <= angle <= spec.joint_upper or not go(angle):
                break
            reading = ctl.average(q_ref, limits, cfg.average_steps)
            if carried_force(spec, reading, 0, ctl.T, ctl.robot.gravity)[0] < POKE_FORCE_N:
                break
            out.append(Moment(joint=0, step=ctl.steps, still=True, reading=reading, readings=cfg.average_steps))
        go(centre)
    q_ref[0] = ctl.reading.q[0] + cfg.hold_bias
    ctl.hold(q_ref)
    return out


def run_poke(robot: Robot, T_world_base, q0, stop_rad: float, band: ContactBand | None,
             cfg: ControlConfig = ControlConfig(), record: bool = False,
             tip_speed_m_s: float = POKE_TIP_SPEED_M_S, slides: int = 0, slide_step_m: float = SLIDE_STEP_M) -> Attempt:
    """One poke: start in the hook ``q0`` (n,) rad at the base pose ``T_world_base`` (4, 4), sweep the
    base joint towards ``stop_rad`` rad with its sweep speed and torque limit until the detector
    fires (``band``; None: never), then settle and read the touch as a wrap does
    (:func:`~explore3d.strategy.encircle.settle_touch`), creeping the reference on until the tip
    presses with :data:`POKE_FORCE_N`; the moment is the mean of :data:`POKE_AVERAGE_STEPS` readings.
    With ``slides`` > 0 the tip then follows the surface (:func:`slide_tip`) ``slides`` steps of
    ``slide_step_m`` each way from the touch, a moment read at each.  Returns an
    :class:`~explore3d.strategy.encircle.Attempt` whose only sweep is the base joint's."""
    spec: ArmSpec = robot.spec
    n = spec.n_links
    cfg = dataclasses.replace(cfg, average_steps=max(cfg.average_steps, POKE_AVERAGE_STEPS))
    ctl = Controller(robot, cfg, T_world_base, record)
    q0 = np.asarray(q0, float)
    ctl.start(q0)
    q_ref = q0.copy()
    ctl.hold(q_ref)
    speeds, torques = sweep_speeds(spec, cfg), sweep_torque_limits(spec, cfg)
    contact = np.zeros(n, dtype=bool)
    contact_step = np.full(n, -1, dtype=int)
    moments = []
    stop = min(stop_rad, spec.joint_upper - cfg.limit_margin)
    R = float(np.linalg.norm(tip_point(spec, q0)[0]))
    speed = min(float(speeds[0]), tip_speed_m_s / R)
    reason = sweep_joint(ctl, 0, q_ref, stop, band, speed, torques[0], True)
    if reason is StopReason.CONTACT:
        contact[0] = True
        contact_step[0] = ctl.steps
        moment = settle_touch(ctl, 0, q_ref, torques[0], contact)
        for i in range(POKE_PRESS_STEPS):  # too light a touch to place: creep the reference on
            if carried_force(spec, moment.reading, 0, ctl.T, robot.gravity)[0] >= POKE_FORCE_N:
                break
            q_ref[0] = ctl.reading.q[0] + (i + 1) * POKE_CREEP_M / R
            moment = settle_touch(ctl, 0, q_ref, torques[0], contact)
        moments.append(moment)
        if slides and moment.still:
            moments += slide_tip(ctl, q_ref, torques[0], R, slides, slide_step_m)
    else:
        ctl.hold(q_ref)
    detect_step = np.full(n, ctl.steps, dtype=int)
    return Attempt(
        T_world_base=np.asarray(T_world_base, dtype=float).copy(), q=ctl.reading.q.copy(), q_ref=q_ref.copy(),
        contact=contact, reasons=(reason,) + (StopReason.ENDED,) * (n - 1), detect_step=detect_step,
        steps=ctl.steps, trajectory=np.array(ctl.traj) if record else None,
        trajectory_ref=np.array(ctl.traj_ref) if record else None,
        trajectory_joint=np.array(ctl.traj_joint, dtype=int) if record else None,
        contact_step=contact_step, moments=tuple(moments), poke=True,
    )
