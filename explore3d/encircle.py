"""The encirclement strategy of the paper (section III), driven by joint error alone.

One *attempt*: the arm starts straight; the most proximal joint sweeps its reference towards the
curl (+ angles) carrying the straight distal links; when any joint's position error leaves its
calibrated free-motion band the swept joint is taken to be in contact: it is held there (optionally
with a small inward bias, the paper's proposal against relaxation) and the next joint sweeps; this
goes on until every joint has made contact or reached its limit.  One *wrap*: several attempts
from one base pose, the base joint stopping a step short of its previous stop angle each time.

The code here reads joint angles and its own commanded references and nothing else about the
world: no contact queries, ray tests or object poses (a test runs a whole exploration with those
PyBullet functions patched to raise).
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

import numpy as np

from .arm import ArmSpec
from .sim import ArmSimulation, SimConfig


class StopReason(enum.Enum):
    """Why a joint's sweep ended."""

    CONTACT = "contact"  #: a joint error left its band
    LIMIT = "limit"  #: the reference reached the joint limit without contact
    STOP_ANGLE = "stop_angle"  #: the base joint reached this attempt's stop angle (attempts after the first)
    TIMEOUT = "timeout"  #: the sweep ran out of steps
    WRAPPED = "wrapped"  #: not swept: the chain before it had already curled a full turn (``max_curl``)


@dataclass(frozen=True)
class ControlConfig:
    """Reference controller and contact detection (SI units).

    Attributes:
        speed: largest reference speed of a swept joint, rad/s.
        tip_speed: the swept joint's speed is also capped so the arm's tip moves at most this fast,
            m/s: joint k sweeps at ``min(speed, tip_speed / L_k)`` with ``L_k`` the length from
            joint k to the tip (proximal joints carry long chains: slower, gentler impacts).
            None: every joint sweeps at ``speed``.
        ramp_time: time over which the swept joint's reference speed ramps up from 0, s.
        band_factor: the contact band is ``band_factor`` x the largest free-motion error ...
        band_margin: ... plus this, rad (covers solver noise the calibration did not see).
        hold_bias: held joints' reference is set this far beyond the angle at contact, rad, in
            the curl direction (the paper's proposed small inward push; 0 holds in place).
        limit_margin: sweeps stop this far short of the joint's upper limit, rad.
        sweep_torque_factor: the swept joint's motor torque limit is this times what free motion
            needs (its gravity bound, :meth:`~explore3d.arm.ArmSpec.gravity_torques`, plus the
            distal chain's inertia bound times the ramp's acceleration ``speed / ramp_time``) ...
        sweep_torque_margin: ... plus this, N m.  Held and distal joints keep the full motor
            torque, so a contact anywhere on the distal chain stalls the swept joint instead of
            knocking a held joint away.
        watch_held: also watch the held (proximal) joints' errors; off, only the swept joint's
            lag and the not-yet-swept (distal) joints' errors signal contact.
        gravity_compensation: the motors cancel the links' weights (from the arm's own model and
            the known base pose); the swept joint's torque limit then leaves gravity out.
        rereference_held: after each detection the held joints' references are reset to their
            measured angles (no held joint stays saturated against the object).
        max_curl: a joint is not swept once the joints before it have curled this much in
            total, rad (2 pi: the chain has gone once around the object; beyond, it would lie
            over itself).
        settle_steps: steps the arm is held still after being reset straight and after each
            sweep (lets the impact of a contact die out before the next joint moves).
        max_sweep_steps: safety cap on the steps of one joint's sweep.
    """

    speed: float = 3.0
    tip_speed: float | None = 0.3
    ramp_time: float = 0.05
    band_factor: float = 1.5
    band_margin: float = 0.02
    hold_bias: float = 0.0
    limit_margin: float = 0.02
    sweep_torque_factor: float = 1.5
    sweep_torque_margin: float = 0.05
    hold_torque_factor: float = 0.0
    other_margin: float = 0.05
    watch_held: bool = False
    gravity_compensation: bool = True
    rereference_held: bool = False
    max_curl: float = 2 * math.pi
    settle_steps: int = 3
    max_sweep_steps: int = 2000

    def __post_init__(self):
        for name in ("speed", "band_factor"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0; got {getattr(self, name)}")
        if self.tip_speed is not None and not self.tip_speed > 0:
            raise ValueError(f"tip_speed must be > 0 m/s or None; got {self.tip_speed}")
        for name in ("ramp_time", "band_margin", "hold_bias", "limit_margin"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0; got {getattr(self, name)}")


@dataclass(frozen=True)
class ContactBand:
    """Free-motion error bands, rad, per joint: ``swept[j]`` bounds the lag of joint j while it
    sweeps; ``other[j]`` bounds |error| of joint j while another joint sweeps."""

    swept: np.ndarray
    other: np.ndarray

    def to_dict(self) -> dict:
        return {"swept_rad": self.swept.tolist(), "other_rad": self.other.tolist()}


@dataclass(frozen=True)
class Attempt:
    """The result of one attempt.

    Attributes:
        T_world_base: (4, 4) the base pose, world frame.
        q: (n,) measured joint angles at final contact, rad.
        q_ref: (n,) references at the end, rad.
        contact: (n,) bool, joint j's sweep ended by a detected contact.
        reasons: StopReason of each joint's sweep.
        detect_step: (n,) int, the step of the attempt at which joint j's sweep ended.
        steps: physics steps taken.
        trajectory: (t, n) measured joint angles at every step when recorded, else None.
        trajectory_ref: (t, n) references at every step when recorded, else None.
    """

    T_world_base: np.ndarray
    q: np.ndarray
    q_ref: np.ndarray
    contact: np.ndarray
    reasons: tuple
    detect_step: np.ndarray
    steps: int
    trajectory: np.ndarray | None = None
    trajectory_ref: np.ndarray | None = None


def sweep_speeds(spec: ArmSpec, cfg: ControlConfig) -> np.ndarray:
    """(n,) sweep speed of each joint, rad/s (see :attr:`ControlConfig.tip_speed`)."""
    w = np.full(spec.n_links, float(cfg.speed))
    if cfg.tip_speed is not None:
        reach = spec.link_length * (spec.n_links - np.arange(spec.n_links))
        w = np.minimum(w, cfg.tip_speed / reach)
    return w


def _ramp_speed(speed: float, ramp_time: float, t: float) -> float:
    if ramp_time <= 0:
        return speed
    return speed * min(1.0, (t + 1e-12) / ramp_time)


def sweep_torque_limits(spec: ArmSpec, cfg: ControlConfig) -> np.ndarray:
    """(n,) motor torque limit, N m, of each joint while it sweeps (see :class:`ControlConfig`)."""
    accel = sweep_speeds(spec, cfg) / max(cfg.ramp_time, 1e-3)
    need = np.array(spec.inertia_bounds()) * accel
    if not cfg.gravity_compensation:
        need = need + np.array(spec.gravity_torques())
    return cfg.sweep_torque_factor * need + cfg.sweep_torque_margin


def run_attempt(sim: ArmSimulation, T_world_base, band: ContactBand | None, cfg: ControlConfig = ControlConfig(),
                base_stop: float | None = None, record: bool = False, _errors: list | None = None) -> Attempt:
    """One attempt from the base pose ``T_world_base`` (4, 4).

    Args:
        sim: the simulation (only set_base / reset_joints / step are used).
        band: the contact band; None disables detection (free-motion calibration).
        base_stop: the base joint's stop angle, rad (None: sweep until contact or limit).
        record: keep the joint angles of every step (for free-space carving).
        _errors: calibration hook; receives (k, err (n,)) for every step when given.
    """
    spec: ArmSpec = sim.spec
    n = spec.n_links
    dt = sim.config.timestep
    sim.set_base(T_world_base)
    q_ref = np.zeros(n)
    sim.reset_joints(q_ref)
    q = q_ref.copy()
    for _ in range(cfg.settle_steps):
        q = sim.step(q_ref, gravity_compensation=cfg.gravity_compensation)
    upper = spec.joint_upper - cfg.limit_margin
    sweep_torques = sweep_torque_limits(spec, cfg)
    speeds = sweep_speeds(spec, cfg)
    contact = np.zeros(n, dtype=bool)
    reasons: list = []
    detect_step = np.zeros(n, dtype=int)
    traj, traj_ref = ([], []) if record else (None, None)
    steps = 0
    for k in range(n):
        stop = upper if (k > 0 or base_stop is None) else min(upper, base_stop)
        reason = StopReason.TIMEOUT
        if k > 0 and q[:k].sum() >= cfg.max_curl:
            reasons.extend([StopReason.WRAPPED] * (n - k))
            detect_step[k:] = steps
            break
        if q_ref[k] >= stop:
            reason = StopReason.STOP_ANGLE if (k == 0 and base_stop is not None) else StopReason.LIMIT
        else:
            dq_ref = np.zeros(n)
            forces = np.array(sim.torques)
            forces[:k] = cfg.hold_torque_factor * sweep_torques[:k] if cfg.hold_torque_factor else forces[:k]
            forces[k] = sweep_torques[k]
            base_err = q_ref - q  # errors of the other joints are judged against their values now
            prev_lag, prev_sig = 0.0, np.zeros(n)
            for i in range(cfg.max_sweep_steps):
                # speed ramps up from rest and down again before the stop angle (no false alarm there)
                wk = speeds[k]
                w = min(_ramp_speed(wk, cfg.ramp_time, i * dt),
                        _ramp_speed(wk, cfg.ramp_time, max(0.0, (stop - q_ref[k]) / wk)))
                w = max(w, wk * 0.05)
                q_ref[k] = min(stop, q_ref[k] + w * dt)
                dq_ref[k] = w if q_ref[k] < stop else 0.0
                q = sim.step(q_ref, dq_ref, forces, gravity_compensation=cfg.gravity_compensation)
                steps += 1
                if record:
                    traj.append(q)
                    traj_ref.append(q_ref.copy())
                # Lag of the swept joint behind its previous reference (the motor aims at the
                # reference one step ahead, so q_ref - q alone reads one step's travel low).
                lag = (q_ref[k] - w * dt) - q[k]
                sig = (q_ref - q) - base_err
                sig[k] = 0.0
                if not cfg.watch_held:
                    sig[:k] = 0.0
                # Mean of this and the previous step: a two-step chatter of a loaded joint cancels,
                # a contact (a persistent error) does not.
                lag2, sig2 = 0.5 * (lag + prev_lag), 0.5 * (sig + prev_sig)
                prev_lag, prev_sig = lag, sig
                if _errors is not None:
                    _errors.append((k, lag2, sig2))
                if band is not None and i > 0 and (lag2 > band.swept[k] or (np.abs(sig2) > band.other).any()):
                    reason = StopReason.CONTACT
                    break
                if q_ref[k] >= stop:
                    reason = StopReason.STOP_ANGLE if (k == 0 and base_stop is not None) else StopReason.LIMIT
                    break
        if reason is StopReason.CONTACT:
            contact[k] = True
            q_ref[k] = q[k] + cfg.hold_bias
            if cfg.rereference_held:
                q_ref[:k] = q[:k] + cfg.hold_bias * contact[:k]
        for _ in range(cfg.settle_steps):
            q = sim.step(q_ref, gravity_compensation=cfg.gravity_compensation)
            steps += 1
        reasons.append(reason)
        detect_step[k] = steps
    return Attempt(
        T_world_base=np.asarray(T_world_base, dtype=float).copy(), q=q.copy(), q_ref=q_ref.copy(), contact=contact,
        reasons=tuple(reasons), detect_step=detect_step, steps=steps,
        trajectory=np.array(traj) if record else None, trajectory_ref=np.array(traj_ref) if record else None,
    )


def run_wrap(sim: ArmSimulation, T_world_base, band: ContactBand, attempts: int = 4, base_step: float = 0.1,
             cfg: ControlConfig = ControlConfig(), record: bool = False) -> list[Attempt]:
    """``attempts`` attempts from one base pose: the first sweeps the base joint until contact;
    each later one stops the base joint ``base_step`` rad short of the previous stop angle."""
    out = []
    stop = None
    for m in range(attempts):
        att = run_attempt(sim, T_world_base, band, cfg, base_stop=stop, record=record)
        out.append(att)
        prev = att.q[0] if stop is None else stop
        stop = prev - base_step
        if stop <= 0:
            break
    return out


def calibrate_band(spec: ArmSpec, cfg: ControlConfig = ControlConfig(), sim_config: SimConfig = SimConfig(),
                   base_transforms=None) -> ContactBand:
    """The free-motion error band: the same sweeps with no object, per joint.

    Every joint sweeps from straight to its limit at ``cfg.speed`` (the motion of an attempt that
    never touches anything) from each base pose in ``base_transforms`` (default: the arm's plane
    vertical and horizontal, the worst and best cases for gravity); the band is
    ``band_factor * max|error| + band_margin`` per joint.
    """
    if base_transforms is None:
        vertical = np.eye(4)
        vertical[:3, :3] = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])  # base +y up: curl against gravity
        vertical_down = np.eye(4)
        vertical_down[:3, :3] = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
        base_transforms = [np.eye(4), vertical, vertical_down]
    n = spec.n_links
    swept = np.zeros(n)
    other = np.zeros(n)
    with ArmSimulation(spec, config=sim_config) as sim:
        for T in base_transforms:
            errs: list = []
            run_attempt(sim, T, None, cfg, _errors=errs)
            for k, lag, sig in errs:
                swept[k] = max(swept[k], lag)
                np.maximum(other, np.abs(sig), out=other)
    return ContactBand(swept=cfg.band_factor * swept + cfg.band_margin,
                       other=cfg.band_factor * other + cfg.other_margin)
