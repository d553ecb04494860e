"""Replaying a recorded wrap with PyBullet's contact report, and what triggered false detections
(evaluation only).

The replay runs the exploration's own controller on a fresh simulation of the true mesh through
the robot interface (:class:`explore3d.robot.interface.Robot`): a wrapper robot passes every command to the
simulated arm and, after each step, reads PyBullet's contact points, which only the evaluation
sees.  Wraps are deterministic (sensor noise seeded by the wrap's index), so the replay reproduces
the recorded attempts exactly.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from explore3d.geometry.sdf import SignedDistance
from explore3d.robot.interface import ForwardingRobot, JointCommand, JointReading, Robot
from explore3d.strategy.explore import run_pose
from explore3d.world.sim import ArmSimulation

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

    if not (0 <= wrap < exploration.n_wraps):
        raise ValueError(f"wrap must be in [0, {exploration.n_wraps}); got {wrap!r}")
    spec, cfg = exploration.spec, exploration.config
    n = spec.n_links
    with ArmSimulation(spec, np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64), cfg.sim) as world:
        robot = world.robot(cfg.sensors)
        robot.reseed((0, wrap))  # as explore() seeds the wrap
        obs = _ContactObservingRobot(world, robot)
        atts = run_pose(obs, exploration.poses[wrap], exploration.band, cfg, record=True)
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




