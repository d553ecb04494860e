"""The ideal skin: what a perfect force-sensitive skin would have reported on the same sweeps
(evaluation only; the paper's future work: compare with a force-sensitive skin).

EVALUATION ONLY: it re-runs a recorded exploration's wraps in a fresh simulation of the true mesh
and reads PyBullet's contact points, which the robot never sees.  Wraps are deterministic (sensor
noise seeded by the wrap's index), so the re-run takes exactly the recorded motions; at each
*reading* of the exploration (every detection step, every settled moment a contact is localised
from, and each attempt's final hold) it keeps every
arm-object contact point PyBullet reports, on the link side (``positionOnA``), with its normal
force.  Hulled the same way as the link points (:func:`explore3d.reconstruction.hull_input.reconstruct_points`),
they separate where the arm touched (the skin) from what the joint signals made of it.

PyBullet's Dantzig solver reports a normal force of 0 for many real contacts (a contact point
inside the margin that the solver did not need); :attr:`SkinContacts.loaded` marks the points
carrying at least :data:`LOADED_FORCE_N`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from explore3d.robot.interface import ForwardingRobot, JointCommand, JointReading, Robot
from explore3d.strategy.explore import run_pose
from explore3d.world.sim import ArmSimulation

__all__ = ["LOADED_FORCE_N", "SkinContacts", "ideal_skin", "surface_coverage", "COVERAGE_RADII_M"]

#: A contact point *carries force* when PyBullet reports at least this normal force, N (well above
#: the solver's round-off; a 10 g link's weight is 0.1 N).
LOADED_FORCE_N = 1.0e-3

#: Coverage is the fraction of the true surface within these distances of a touch, metres.
COVERAGE_RADII_M = (3.0e-3, 6.0e-3)


@dataclass(frozen=True)
class SkinContacts:
    """The ideal skin's contacts over an exploration (m contact points).

    Attributes:
        points: (m, 3) contact points on the links' surfaces, world frame, metres.
        normal_force_n: (m,) PyBullet's normal force of each point, N.
        link, wrap, attempt: (m,) int: where each point came from.
        kind: (m,) str: when it was read: ``"detect"`` (a detection step), ``"moment"`` (the
            physics state a settled reading reports, :attr:`explore3d.strategy.encircle.Attempt.moments`;
            ``moment`` gives its index in the attempt) or ``"final"`` (an attempt's final hold).
        moment: (m,) int: the index of the moment in its attempt (-1 for other kinds).
    """

    points: np.ndarray
    normal_force_n: np.ndarray
    link: np.ndarray
    wrap: np.ndarray
    attempt: np.ndarray
    kind: np.ndarray
    moment: np.ndarray

    @property
    def final(self) -> np.ndarray:
        """(m,) bool: read at an attempt's final hold."""
        return self.kind == "final"

    @property
    def loaded(self) -> np.ndarray:
        """(m,) bool: the points carrying at least :data:`LOADED_FORCE_N`."""
        return self.normal_force_n >= LOADED_FORCE_N

    def __len__(self) -> int:
        return len(self.points)


class _SkinRobot(ForwardingRobot):
    """The simulated arm's robot interface, passed through; at the wanted steps of each motion it
    reads PyBullet's arm-object contact points (the ideal skin)."""

    def __init__(self, world, robot: Robot, wanted: list):
        super().__init__(robot)
        self._world, self._wanted = world, wanted
        self._motion, self._k = -1, 0
        self.rows: list = []  # (attempt, kind, moment index, link, point (3,), force)

    def on_start(self, T_world_base, q0, reading: JointReading) -> None:
        self._motion += 1
        self._k = 0

    def on_step(self, command: JointCommand, reading: JointReading) -> None:
        self._k += 1
        kinds = self._wanted[self._motion].get(self._k, ()) if self._motion < len(self._wanted) else ()
        if kinds:
            w = self._world
            cps = [c for c in w.client.getContactPoints(bodyA=w.arm, bodyB=w.object) if 0 <= c[3] < self.spec.n_links]
            for kind, mi in kinds:
                for c in cps:
                    self.rows.append((self._motion, kind, mi, c[3], c[5], c[9]))


def _wanted_steps(attempts, delay_steps: int) -> list:
    """Per attempt, {physics step within the motion (1-based): [(kind, moment index), ...]}."""
    out = []
    for att in attempts:
        d: dict = {}
        for k in np.flatnonzero(att.contact):
            d.setdefault(int(att.contact_step[k]), []).append(("detect", -1))
        for mi, m in enumerate(att.moments):  # the reading at step s reports the state of step s - delay
            d.setdefault(max(int(m.step) - delay_steps, 1), []).append(("moment", mi))
        d.setdefault(int(att.steps), []).append(("final", -1))
        out.append(d)
    return out


def ideal_skin(exploration, mesh) -> SkinContacts:
    """Every arm-object contact point PyBullet reports at the readings of ``exploration``
    (detection steps and final holds), re-running its wraps on ``mesh`` (the same closed trimesh,
    world frame).  Costs about as long as the exploration itself (one process)."""

    cfg = exploration.config
    rows = {k: [] for k in ("p", "f", "l", "w", "a", "kind", "mi")}
    V, F = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
    for wi, (pose, atts) in enumerate(zip(exploration.poses, exploration.attempts)):
        with ArmSimulation(exploration.spec, V, F, cfg.sim) as world:  # a world per wrap, as explore()
            robot = world.robot(cfg.sensors)
            robot.reseed((0, wi))  # as explore() seeds the wrap
            skin = _SkinRobot(world, robot, _wanted_steps(atts, cfg.sensors.delay_steps))
            again = run_pose(skin, pose, exploration.band, cfg)
        if len(again) != len(atts) or not all(np.array_equal(a.q, b.q) for a, b in zip(again, atts)):
            raise RuntimeError(f"wrap {wi}: the re-run did not reproduce the recorded attempts; the ideal "
                               "skin needs the exploration's own mesh, arm and configuration")
        for ai, kind, mi, link, p, f in skin.rows:
            rows["p"].append(p)
            rows["f"].append(f)
            rows["l"].append(link)
            rows["w"].append(wi)
            rows["a"].append(ai)
            rows["kind"].append(kind)
            rows["mi"].append(mi)
    return SkinContacts(points=np.array(rows["p"], dtype=float).reshape(-1, 3),
                        normal_force_n=np.array(rows["f"], dtype=float), link=np.array(rows["l"], dtype=int),
                        wrap=np.array(rows["w"], dtype=int), attempt=np.array(rows["a"], dtype=int),
                        kind=np.array(rows["kind"], dtype="<U6"), moment=np.array(rows["mi"], dtype=int))


def surface_coverage(truth, touches, radii_m=COVERAGE_RADII_M, n_samples: int = 20000, seed: int = 0) -> tuple:
    """Fraction of the true surface within each of ``radii_m`` (metres) of a touch.

    Args:
        truth: the true closed trimesh (3D) or shapely polygon (planar), world frame, metres.
        touches: (m, d) touch points, metres (d = 3, or 2 for a polygon).
        n_samples: surface (boundary) samples, seeded by ``seed``.

    Returns:
        one fraction in [0, 1] per radius.
    """
    T = np.asarray(touches, dtype=float)
    if hasattr(truth, "faces"):
        S = trimesh.sample.sample_surface(truth, n_samples, seed=seed)[0]
    else:
        ring = truth.exterior
        S = np.array([ring.interpolate(t, normalized=True).coords[0] for t in np.linspace(0, 1, n_samples,
                                                                                          endpoint=False)])
    if len(T) == 0:
        return tuple(0.0 for _ in radii_m)
    d, _ = cKDTree(T[:, : S.shape[1]]).query(S)
    return tuple(float(np.mean(d <= r)) for r in radii_m)
