"""The scene the object sits in: floating and fixed (the paper's idealised world), or resting on a
table under gravity with weight and friction, in a world that persists across a run's wraps.

:class:`SceneConfig` says which idealisations hold (every one can be turned on or off, for the
ablation in BENCHMARKS.md); :func:`settle_scene` builds the evaluation's setup of a run: it drops
the object onto the table, lets it come to rest and reads its pose (the truth the estimate is
scored against).  That is the evaluation's business, like the mesh itself: the exploration gets
only what a robot would be given, the rough bound and the table's height (:attr:`SceneSetup.table_z`).

Dynamic objects in PyBullet collide as convex shapes: a convex object is its own convex hull; a
non-convex one is split into convex parts by PyBullet's V-HACD (:func:`convex_parts`), and the
truth is then the union of those parts, the shape the arm actually meets.

Units: metres, kilograms, seconds, radians.  Poses are (4, 4) homogeneous transforms.
"""
from __future__ import annotations

import dataclasses
import functools
import math
import os
import tempfile
from dataclasses import asdict, dataclass

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from explore3d.arm.urdf import load_arm
from explore3d.core.defaults import SCENE_NAMES  # the named scenes of ``--scene``
from explore3d.core.settings import SceneConfig, SimConfig
from explore3d.core.validate import check_field
from explore3d.strategy.encircle import ControlConfig, force_budget_n
from explore3d.strategy.explore import ExploreConfig
from explore3d.world.parts import _union, convex_parts
from explore3d.world.sim import ArmSimulation

__all__ = ["SceneConfig", "SceneSetup", "SCENE_NAMES", "convex_parts", "settle_scene", "pose_drift"]


@dataclass(frozen=True)
class SceneSetup:
    """A settled scene: what the world is built from, and the evaluation's truth.

    Attributes:
        config: the scene.
        table_z: the table top's height, world z, m (None: no table).  Told to the robot.
        truth: the object as it rests (closed trimesh, world frame, m): the evaluation's truth.
        parts: the object's convex parts (resting objects; [(vertices (v, 3), faces (f, 3))] in the
            body frame, whose origin is the centre of mass); () for a fixed object.
        T_object: (4, 4) the settled body pose, world frame (resting objects; identity otherwise).
        mass_kg: the object's mass (0 for a fixed object).
        settle_s: simulated time the object took to come to rest, s.
    """

    config: SceneConfig
    table_z: float | None
    truth: object
    parts: tuple = ()
    T_object: np.ndarray = None
    mass_kg: float = 0.0
    settle_s: float = 0.0

    def to_dict(self) -> dict:
        """JSON-ready: the config, the table height, mass, settle time and settled pose."""
        return {"config": self.config.to_dict(), "table_z_m": self.table_z, "object_mass_kg": self.mass_kg,
                "settle_s": self.settle_s,
                "T_object_settled": None if self.T_object is None else np.asarray(self.T_object).tolist()}


def _pose(client, body) -> np.ndarray:
    pos, quat = client.getBasePositionAndOrientation(body)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat(quat).as_matrix()
    T[:3, 3] = pos
    return T


def pose_drift(T_a, T_b) -> tuple[float, float]:
    """Translation (m) and rotation angle (rad) between two (4, 4) poses."""
    T_a, T_b = np.asarray(T_a, float), np.asarray(T_b, float)
    d = float(np.linalg.norm(T_b[:3, 3] - T_a[:3, 3]))
    R = T_a[:3, :3].T @ T_b[:3, :3]
    return d, float(math.acos(max(-1.0, min(1.0, (np.trace(R) - 1.0) / 2.0))))


def settle_scene(mesh, config: SceneConfig, spec=None, sim=None) -> SceneSetup:
    """The evaluation's setup of a run in ``config``'s scene (reads the object's pose: not for
    the exploration).

    The table top is put at the lowest vertex of ``mesh`` (closed trimesh, metres, world frame);
    a resting object is built from its convex parts at its centre of mass and stepped until its
    speed has stayed below 0.1 mm/s and 1 mrad/s for 0.2 s (at most ``config.settle_time``), with
    the arm far away.  Its pose then places the truth.

    Args:
        spec, sim: the arm (:class:`~explore3d.arm.spec.ArmSpec`, default the built-in default arm)
            and the physics settings (:class:`~explore3d.core.settings.SimConfig`) of the world.
    """

    if not isinstance(config, SceneConfig):
        raise ValueError(f"scene must be a SceneConfig; got {type(config).__name__}")
    table_z = float(mesh.bounds[0, 2]) if config.table else None
    if not config.resting:
        return SceneSetup(config=config, table_z=table_z, truth=mesh, T_object=np.eye(4))
    parts = convex_parts(mesh)
    body = _union(parts) if len(parts) > 1 else trimesh.Trimesh(*parts[0], process=True)
    com = np.asarray(body.center_mass, float)
    mass = float(config.density * body.volume)
    local = tuple((V - com, F) for V, F in parts)
    T0 = np.eye(4)
    T0[:3, 3] = com
    start = SceneSetup(config=config, table_z=table_z, truth=body, parts=local, T_object=T0, mass_kg=mass)
    spec = load_arm("default") if spec is None else spec
    sim = SimConfig() if sim is None else sim
    with ArmSimulation(spec, config=sim, scene=start) as world:
        p, obj = world.client, world.object
        dt = sim.timestep
        still, steps = 0, 0
        for steps in range(1, int(math.ceil(config.settle_time / dt)) + 1):
            world.step_passive()
            v, w = p.getBaseVelocity(obj)
            still = still + 1 if (np.linalg.norm(v) < 1e-4 and np.linalg.norm(w) < 1e-3) else 0
            if still * dt >= 0.2:
                break
        T = _pose(p, obj)
    truth = body.copy()
    truth.apply_transform(T @ np.linalg.inv(T0))
    return SceneSetup(config=config, table_z=table_z, truth=truth, parts=local, T_object=T, mass_kg=mass,
                      settle_s=steps * dt)


def object_pose(world) -> np.ndarray:
    """(4, 4) the world's object body pose (evaluation only: the exploration never calls it)."""
    return _pose(world.client, world.object)


#: the table scene's contact detector (:attr:`~explore3d.strategy.encircle.ControlConfig.detector`), chosen by
#: measurement (BENCHMARKS.md, "Touch without pushing"): on the resting cube, box and L-block it gave lower volume
#: errors and less drift than the stall detector
TABLE_DETECTOR = "torque"


def scene_explore_config(name: str = "table", spec=None, detector: str | None = None, **kw):
    """The :class:`~explore3d.strategy.explore.ExploreConfig` of a named scene (``--scene``): ``"ideal"`` is
    ExploreConfig's default; ``"table"`` adds :meth:`SceneConfig.named` ("table"), the gentle
    sweeps of :meth:`~explore3d.strategy.encircle.ControlConfig.gentle` with their ramp lengthened to
    keep within the force budget (:meth:`~explore3d.strategy.encircle.ControlConfig.within_budget`:
    half the static friction of :attr:`SceneConfig.least_mass_kg` on the table; the arm ``spec``,
    name or ArmSpec, default the built-in default arm) unless ``kw`` gives a ``control``,
    a 5% model mass error (:attr:`~explore3d.core.settings.SimConfig.mass_error`, seed 0) and PyBullet's
    Dantzig solver with a global constraint-force mixing of 1e-6
    (:attr:`~explore3d.core.settings.SimConfig.global_cfm`; on ``kw``'s ``sim`` if given), the paper's link points as the hull's
    input and no probes (unless ``kw`` says otherwise).  ``detector`` (``"stall"`` or
    ``"torque"``, :attr:`~explore3d.strategy.encircle.ControlConfig.detector`; None: the scene's
    default, :data:`TABLE_DETECTOR` on the table, ``"stall"`` in the ideal scene) sets the contact
    detector of the scene's controller (not of a ``control`` in ``kw``); on the table the torque
    detector's sweeps hold where they stopped after a detection
    (``press_while_settling=False``), the stall detector's press on at the budget as before.
    Other keyword arguments are ExploreConfig's.

    Why link points: the gentle sweeps press with a few tens of mN, and the localisation's
    precision is the torque noise over the force (the profile width about 3 mm at 0.25 N even
    with averaged readings; ``scripts/studies/table_uncertainty_study.py`` on the resting cube: 2 of 703
    contacts within the hull's 0.5 mm; the hull of all of them 28.4% volume error, of those within
    2-5 mm 32-36%, the link points 17.1%).  Probes aim at the localised estimate, so none.

    Why the solver (``scripts/studies/physics_study.py``, BENCHMARKS "Table scene: the solver"): with a
    body resting on the table by friction, PyBullet's Dantzig MLCP, which spans the whole world, is
    degenerate and falls back to sequential impulses for every constraint, the arm's motors
    included: a swing in free space 11 mm above the cube lags its reference by up to 313 mrad
    (3.9 mrad with no object) and every joint fires a false contact.  The sequential-impulse
    solver lags as much even in an empty world (its motors do not converge), which put the
    localised contacts a median 13 mm off the surface.  A constraint-force mixing of 1e-7 to 1e-5
    regularises the MLCP: the arm's torques are bit-identical to the empty world's, and at the
    force budget the contacts come a median 2-3 mm off the surface, none false."""

    scene = SceneConfig.named(name)
    if name == "table":
        if "control" not in kw:
            budget = force_budget_n(scene.least_mass_kg, scene.table_friction)
            control = ControlConfig.within_budget(load_arm("default" if spec is None else spec), budget)
            detector = TABLE_DETECTOR if detector is None else detector
            # the torque detector stops a sweep at the first touch on any joint; holding the stopped pose then
            # (rather than pressing on at the sweep's limit) keeps the object where it is (docs/scene.md)
            kw["control"] = dataclasses.replace(control, detector=detector, press_while_settling=detector == "stall")
        kw.setdefault("points", "links")
        kw.setdefault("probes", None)
        kw["sim"] = dataclasses.replace(kw.get("sim", SimConfig()), mass_error=0.05, solver="dantzig", global_cfm=1e-6)
    elif detector is not None and "control" not in kw:
        kw["control"] = ControlConfig(detector=detector)
    return ExploreConfig(scene=scene, **kw)


class SceneWatch:
    """Evaluation only: follows the object through an exploration (pass :meth:`after_wrap` to
    :func:`~explore3d.world.explore.explore` or :func:`~explore3d.app.pipeline.run`; the exploration never
    sees it).  After every wrap it reads the object's pose; during the wrap, after every step,
    whether any link touches the object (PyBullet's contact points), so each detection can be
    judged (:meth:`summary`).

    Args:
        setup: the settled scene (:func:`settle_scene`).
    """

    #: a detection is true when a link touched the object at one of the last this many steps
    TOUCH_WINDOW_STEPS = 10

    #: a touch's *held* force is the largest mean of the summed normal force over this many
    #: consecutive steps (42 ms at 240 Hz): what pushes a resting object, where the peak of a single
    #: step is mostly the impact impulse of the first step of contact, over before any reading.
    HELD_FORCE_STEPS = 10

    def __init__(self, setup: SceneSetup):
        self.setup = setup
        self.poses: list[np.ndarray] = []
        self.touch: list[np.ndarray] = []
        self.force: list[np.ndarray] = []
        self._steps: list[bool] = []
        self._force: list[float] = []

    def _observe(self, world) -> None:
        cps = world.client.getContactPoints(world.arm, world.object)
        self._steps.append(bool(cps))
        self._force.append(float(sum(c[9] for c in cps)))

    def after_wrap(self, index: int, world) -> None:
        """The hook: ``index`` -1 when a world is ready (watch its steps), else after wrap
        ``index``: record its steps and the object's pose."""
        if index < 0:
            world.step_observer = self._observe
            self._steps, self._force = [], []
            return
        self.touch.append(np.array(self._steps, dtype=bool))
        self.force.append(np.array(self._force, dtype=float))
        self._steps, self._force = [], []
        self.poses.append(object_pose(world) if world.object is not None else np.eye(4))

    def detections(self, exploration) -> tuple[int, int]:
        """(detections, false ones) over the watched wraps: a detection is false when no link
        touched the object in the :data:`TOUCH_WINDOW_STEPS` steps up to it."""
        n = bad = 0
        for w, atts in enumerate(exploration.attempts):
            if w >= len(self.touch) or not len(self.touch[w]):
                continue
            t, off = self.touch[w], 0
            for a in atts:
                for s in a.contact_step[a.contact_step >= 0]:
                    hi = off + int(s)
                    n += 1
                    bad += not t[max(0, hi - self.TOUCH_WINDOW_STEPS):hi].any()
                off += int(a.steps)
        return n, bad

    def touch_forces(self, exploration) -> tuple[np.ndarray, np.ndarray]:
        """(peak, held) normal force of every detected touch, N (evaluation only: PyBullet's
        contact forces between the arm and the object, summed over the arm's links): over the
        steps of the sweep that detected it and its settle, the largest single step's force and
        the largest mean over :data:`HELD_FORCE_STEPS` consecutive steps."""
        peak, held = [], []
        m = self.HELD_FORCE_STEPS
        for w, atts in enumerate(exploration.attempts):
            if w >= len(self.force) or not len(self.force[w]):
                continue
            f, off = self.force[w], 0
            for a in atts:
                starts = np.concatenate([[0], np.asarray(a.detect_step)[:-1]])
                for k in np.flatnonzero(np.asarray(a.contact_step) >= 0):
                    seg = f[off + int(starts[k]):off + int(a.detect_step[k])]
                    if not len(seg):
                        continue
                    peak.append(float(seg.max()))
                    c = np.cumsum(np.concatenate([[0.0], seg]))
                    held.append(float(((c[m:] - c[:-m]) / m).max()) if len(seg) >= m else float(seg.mean()))
                off += int(a.steps)
        return np.array(peak), np.array(held)

    def summary(self, exploration) -> dict:
        """JSON-ready: the object's drift from its settled pose after every wrap and at the end
        (translation m, rotation deg), the false detections of the watched wraps, and the wraps the
        robot flagged (:attr:`~explore3d.strategy.explore.Exploration.moved`) and repeated."""
        T0 = self.setup.T_object if self.setup.T_object is not None else np.eye(4)
        drift = [pose_drift(T0, T) for T in self.poses] if self.setup.parts else []
        n, bad = self.detections(exploration)
        per_wrap = [pose_drift(a, b) for a, b in zip([T0] + self.poses[:-1], self.poses)] if self.setup.parts else []
        moved_true = [i for i, (d, r) in enumerate(per_wrap) if d > 1e-3 or r > math.radians(1.0)]
        out = {
            "drift_m": drift[-1][0] if drift else 0.0,
            "drift_deg": math.degrees(drift[-1][1]) if drift else 0.0,
            "max_drift_m": max((d for d, _ in drift), default=0.0),
            "drift_after_wrap_m": [d for d, _ in drift],
            "drift_after_wrap_deg": [math.degrees(r) for _, r in drift],
            "wraps_moving_object": moved_true,
            "detections_watched": n, "false_detections": bad,
            "false_detection_fraction": bad / n if n else 0.0,
            "touch_window_steps": self.TOUCH_WINDOW_STEPS,
        }
        if exploration.moved is not None:
            out["wraps_flagged_moved"] = np.nonzero(exploration.moved)[0].tolist()
            out["wraps_redone"] = np.nonzero(exploration.redone)[0].tolist()
        out["registrations"] = [dict(r) for r in exploration.registrations]
        peak, held = self.touch_forces(exploration)

        def stats(x):
            return {"median": float(np.median(x)), "p95": float(np.percentile(x, 95)), "max": float(x.max())} if len(x) else None
        out["touch_force_n"] = {"touches": int(len(peak)), "peak": stats(peak), "held": stats(held),
                                "held_steps": self.HELD_FORCE_STEPS}
        return out
