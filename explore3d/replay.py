"""Replaying a recorded wrap with PyBullet's contact report, and what triggered false detections
(evaluation only).

The replay runs the exploration's own controller on a fresh simulation of the true mesh through
the robot interface (:class:`explore3d.robot.Robot`): a wrapper robot passes every command to the
simulated arm and, after each step, reads PyBullet's contact points, which only the evaluation
sees.  Wraps are deterministic (sensor noise seeded by the wrap's index), so the replay reproduces
the recorded attempts exactly.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .quality import FALSE_DETECTION_TOL_M, TOUCH_TOL_M, _q, detection_records
from .robot import ForwardingRobot, JointCommand, JointReading, Robot
from .sdf import SignedDistance

__all__ = ["FalseDetectionDiagnosis", "WrapReplay", "diagnose_false_detections", "replay_wrap"]


@dataclass(frozen=True)
class WrapReplay:
    """One wrap re-simulated step by step with PyBullet's contact report (evaluation only).

    Every physics step of the wrap (settle steps included), in order:

    Attributes:
        q_ref, q: (s, n) commanded references and measured joint angles after the step, rad.
        forces: (s, n) motor torque limits sent, N m (the arm's full torques in settle steps).
        motor_torque_nm: (s, n) the torque each motor applied in the step, N m (PyBullet's
            ``appliedJointMotorTorque``; equal to ``forces`` in size when a motor is saturated).
        contact_distance_m: (s, n) per link the smallest PyBullet contact distance with the
            object after the step (its geometric gap minus the mesh margin; +inf: no contact point).
        normal_force_n: (s, n) per link the summed normal force of its contact points, N.
        attempt: (s,) int, the attempt each step belongs to.
        sweep_joint: (s,) int, the joint sweeping at the step (-1 in settle steps).
        base_err: per attempt, a dict {joint k: (n,) q_ref - q just before k's sweep, rad}.
        identical: the replay reproduced the recorded attempts bit for bit.
    """

    q_ref: np.ndarray
    q: np.ndarray
    forces: np.ndarray
    motor_torque_nm: np.ndarray
    contact_distance_m: np.ndarray
    normal_force_n: np.ndarray
    attempt: np.ndarray
    sweep_joint: np.ndarray
    base_err: tuple
    identical: bool


class _ContactObservingRobot(ForwardingRobot):
    """The simulated arm's robot interface, passed through unchanged; after every step it also
    logs the command, the reading, and PyBullet's contacts of each link with the object."""

    def __init__(self, world, robot: Robot):
        super().__init__(robot)
        self._world = world
        self.log: dict = {k: [] for k in ("q_ref", "q", "forces", "torque", "dist", "force")}
        self.starts: list = []
        self._full = np.array(robot.spec.joint_torques())

    def on_start(self, T_world_base, q0, reading: JointReading) -> None:
        self.starts.append(len(self.log["q"]))

    def on_step(self, command: JointCommand, r: JointReading) -> None:
        n = self.spec.n_links
        w = self._world
        d, f = np.full(n, np.inf), np.zeros(n)
        for c in w.client.getContactPoints(bodyA=w.arm, bodyB=w.object):
            j = c[3]
            if 0 <= j < n:
                d[j] = min(d[j], c[8])
                f[j] += c[9]
        lim = np.minimum(command.torque_limit, self._full)
        self.log["q_ref"].append(np.array(command.q_ref, dtype=float))
        self.log["q"].append(r.q.copy())
        self.log["torque"].append(r.tau.copy())
        self.log["forces"].append(lim)
        self.log["dist"].append(d)
        self.log["force"].append(f)


def replay_wrap(exploration, mesh, wrap: int) -> WrapReplay:
    """Re-run wrap ``wrap`` of ``exploration`` in a fresh simulation of ``mesh`` (the same closed
    trimesh, world frame) with the exploration's own controller and sensing, logging every control
    step and PyBullet's contact points (an oracle the exploration never sees).  Wraps are
    deterministic, so the replay reproduces the recorded attempts exactly (checked: ``identical``)."""
    from .encircle import run_wrap
    from .sim import ArmSimulation

    if not (0 <= wrap < exploration.n_wraps):
        raise ValueError(f"wrap must be in [0, {exploration.n_wraps}); got {wrap!r}")
    spec, cfg = exploration.spec, exploration.config
    n = spec.n_links
    with ArmSimulation(spec, np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64), cfg.sim) as world:
        robot = world.robot(cfg.sensors)
        robot.reseed((0, wrap))  # as explore() seeds the wrap
        obs = _ContactObservingRobot(world, robot)
        atts = run_wrap(obs, exploration.poses[wrap].T_world_base, exploration.band, attempts=cfg.attempts,
                        base_step=cfg.base_step, cfg=cfg.control, record=True, curl=cfg.curl_back)
    log, starts = obs.log, obs.starts
    rec = exploration.attempts[wrap]
    identical = len(atts) == len(rec) and all(
        np.array_equal(a.q, b.q) and (b.trajectory is None or np.array_equal(a.trajectory, b.trajectory))
        for a, b in zip(atts, rec))
    Qr, Q, F = (np.array(log[k]) for k in ("q_ref", "q", "forces"))
    s = len(Q)
    attempt = np.searchsorted(np.array(starts), np.arange(s), side="right") - 1
    changed = Qr != np.vstack([np.zeros((1, n)), Qr[:-1]])
    # a sweep step sends a reduced torque limit to the swept joint and moves that joint's reference
    # (a contact's pressing settle keeps the reduced limit but holds the reference still)
    reduced = F < np.asarray(spec.joint_torques())[None, :]  # settle steps hold with the full torques
    k_red = np.argmax(reduced, axis=1)
    sweeping = reduced.any(axis=1) & changed[np.arange(s), k_red]
    top = np.where(changed.any(axis=1), n - 1 - np.argmax(changed[:, ::-1], axis=1), -1)
    sweep_joint = np.full(s, -1)
    for t in np.flatnonzero(sweeping):  # the highest joint whose reference moved; else as before
        sweep_joint[t] = top[t] if top[t] >= 0 else (sweep_joint[t - 1] if t else 0)
    base = []
    for a in range(len(starts)):
        idx = np.flatnonzero(attempt == a)
        d = {}
        for t in idx:
            k = int(sweep_joint[t])
            if k >= 0 and k not in d and t - 1 >= idx[0]:
                d[k] = Qr[t - 1] - Q[t - 1]
        base.append(d)
    return WrapReplay(q_ref=Qr, q=Q, forces=F, motor_torque_nm=np.array(log["torque"]), contact_distance_m=np.array(log["dist"]),
                      normal_force_n=np.array(log["force"]), attempt=attempt, sweep_joint=sweep_joint,
                      base_err=tuple(base), identical=bool(identical))


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
