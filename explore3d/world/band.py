"""Calibrating the contact detector: every joint's band from measurement.

:func:`calibrate_band` measures, for one arm, controller, physics and sensing setting, how large
the detector's signals (:mod:`explore3d.feeling.detect`) get when nothing new is touched:

1. **Free motion.**  Every joint k sweeps alone, from the straight arm to its limit (the motion
   of its sweep in an attempt, with the longest and heaviest distal chain), in the base
   orientations that bound gravity's effect: the arm's plane horizontal (gravity along the joint
   axes), and vertical with the curl upwards and downwards (gravity in the plane; a sweep then
   passes through every angle to gravity).  Planar explorations use the horizontal plane only.
   Sensing is the run's own (noise, quantisation, delay).  A step at which the arm's model puts
   two of its own non-adjacent bodies within :func:`self_contact_tolerance_m` of each other (the
   arm touching itself, :mod:`explore3d.arm.selfcontact`) is not free motion and is not recorded
   (counted in ``provenance["free_self_contact_steps"]``; measured: a single bent joint of the
   built-in arms never brings two bodies that close, the count is 0).
2. **Impacts** on a known calibration object (the 60 mm ball of
   :func:`explore3d.world.objects.calibration_sphere`, never the object under test): full attempts
   from a few wrap poses around it.  A link held against the ball, or struck by it, shakes the rest
   of the chain; a sweep step counts as *contact-free* when, by the arm's own model at the sensed
   angles, the swept link and every distal link are farther than :func:`contact_tolerance_m` from
   the known ball and no two non-adjacent bodies of the arm were within
   :func:`self_contact_tolerance_m` of each other at any of the sweep's last
   :data:`~explore3d.strategy.encircle.SELF_CONTACT_WINDOW_STEPS` readings (a chain curled round the object
   can touch itself: contact, not noise; such steps are counted per pass in
   ``"self_contact_steps"``, the sweeps the controller ended as self-contacts in
   ``"self_contacts"``).  The window matters: the simulated tip link lying on the base block
   flips off it within one physics step (Dantzig's solution; 0.42 rad in one step of small16's
   calibration, the model's distance 0 -> 11 mm), so the next reading is clear of the block yet
   carries the flip; taken as contact-free it gave joint 14 of a 16-link arm a band of 3.4 rad
   and that joint never detected the cube (its tip link sank 10 mm into it).  The signals of contact-free steps are what an impact does to the other joints.
   In the *measure* pass a contact-free step never ends a sweep (the known object says nothing
   was touched) and its signals are recorded; near the ball the detector, with the bands measured
   so far, decides, so the chain presses and holds as it will in a run.  A *verify* pass then
   runs the same wraps with the final bands alone and counts detections at contact-free steps:
   false detections on the ball, reported in ``provenance["impact_passes"]``.

The band of each joint is ``ControlConfig.band_factor`` times the largest contact-free signal
measured in 1 and 2.  The result is cached once per setting, in memory and on disk
(``$EXPLORE3D_CACHE_DIR``, default ``~/.cache/explore3d``), so a run pays for it at most once.
"""
from __future__ import annotations

import collections
import contextlib
import dataclasses
import functools
import hashlib
import json
import logging
import math
import os
import time
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from explore3d import __version__
from explore3d.arm.kinematics import link_transforms
from explore3d.arm.selfcontact import self_contact_pairs
from explore3d.arm.spec import ArmSpec
from explore3d.core.io import atomic_write_text, exclusive_lock
from explore3d.core.settings import SimConfig
from explore3d.feeling.detect import ContactBand, SweepDetector
from explore3d.geometry.directions import planar_wrap_poses, spatial_wrap_poses
from explore3d.robot.sensing import SensorConfig
from explore3d.strategy.encircle import (
    SELF_CONTACT_WINDOW_STEPS,
    ControlConfig,
    Controller,
    StopReason,
    run_attempt,
    sweep_joint,
    sweep_speeds,
    sweep_torque_limits,
)
from explore3d.world.objects import CALIBRATION_SPHERE_RADIUS_M, calibration_sphere
from explore3d.world.sim import ArmSimulation

__all__ = ["calibrate_band", "cached_band", "contact_tolerance_m", "self_contact_tolerance_m", "box_sphere_distance",
           "BAND_PROTOCOL_VERSION",
           "gravity_bounding_bases"]

log = logging.getLogger(__name__)

#: Bumped whenever the calibration procedure or the controller it runs changes (old cache entries
#: are then ignored).  4: the pressing settle after each contact (explore3d.strategy.encircle).  5: the arm
#: collides with itself; self-contacts end sweeps (StopReason.SELF) and are not contact-free steps.
#: 6: nor is a step within SELF_CONTACT_WINDOW_STEPS readings of one; the attempt ends at a self-contact.
BAND_PROTOCOL_VERSION = 6  # the torque detector's bands (issue 40) came with no change to the stall bands

#: Wrap poses of the impact phase: 3D, plane normals through the ball's centre (one approach each).
IMPACT_NORMALS_3D = 6
#: Planar: approach directions.
IMPACT_DIRECTIONS_PLANAR = 3


def gravity_bounding_bases() -> list[np.ndarray]:
    """The (4, 4) base orientations of the free-motion calibration: the arm's plane horizontal,
    vertical curling upwards (base +y up), vertical curling downwards."""
    up, down = np.eye(4), np.eye(4)
    up[:3, :3] = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
    down[:3, :3] = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
    return [np.eye(4), up, down]


#: The known calibration block: edge lengths, metres (distinct from every built-in object: the
#: cube is 80 mm, the box 100 x 60 x 40 mm), turned by :data:`CALIBRATION_BLOCK_ROTVEC` so that
#: no edge lies along a wrap plane's axes.  With the 60 mm ball it spans the contact types a run
#: meets: the ball's point contacts on a curved surface, the block's faces, edges and corners.
CALIBRATION_BLOCK_EXTENTS_M = (0.07, 0.045, 0.03)
CALIBRATION_BLOCK_ROTVEC = (0.3, -0.5, 0.2)

#: Sampling pitch of a link box's surface when measuring its distance to the block, metres; the
#: sampled distance overestimates the true one by at most pitch / sqrt(2).
LINK_SAMPLE_PITCH_M = 2.0e-3


def calibration_block_pose() -> np.ndarray:
    """(4, 4) ``T_world_block`` of the calibration block (centred at the origin, turned)."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(CALIBRATION_BLOCK_ROTVEC).as_matrix()
    return T


def calibration_block():
    """The known calibration block as a closed trimesh in its world pose."""
    return trimesh.creation.box(extents=CALIBRATION_BLOCK_EXTENTS_M, transform=calibration_block_pose())


def _link_samples(spec: ArmSpec, pitch: float) -> np.ndarray:
    """(k, 3) points on a link box's surface (corners, edges and faces on a grid of ``pitch``),
    link frame, metres (read-only; computed once per link size and pitch: the calibration asks
    for them at every step)."""
    return _box_surface_samples(float(spec.link_length), float(spec.link_width), float(spec.link_height), float(pitch))


@functools.lru_cache(maxsize=16)
def _box_surface_samples(length: float, width: float, height: float, pitch: float) -> np.ndarray:
    axes = [np.linspace(lo, hi, max(2, int(np.ceil((hi - lo) / pitch)) + 1)) for lo, hi in
            ((0.0, length), (-width / 2, width / 2), (-height / 2, height / 2))]
    X, Y, Z = np.meshgrid(*axes, indexing="ij")
    P = np.stack([X, Y, Z], axis=-1).reshape(-1, 3)
    on_surface = np.zeros(len(P), dtype=bool)
    for i, a in enumerate(axes):
        on_surface |= np.isclose(P[:, i], a[0]) | np.isclose(P[:, i], a[-1])
    out = P[on_surface]
    out.flags.writeable = False
    return out


def box_box_distance(spec: ArmSpec, T_world_link, T_world_box, extents, pitch: float = LINK_SAMPLE_PITCH_M) -> np.ndarray:
    """(m,) distance, metres, from each link box (frames ``T_world_link`` (m, 4, 4)) to a box of
    ``extents`` (3,) metres centred at ``T_world_box`` (4, 4): the smallest exact point-to-box
    distance over the link surface sampled at ``pitch``, minus ``pitch / sqrt(2)`` (so never more
    than the true distance); negative when a sample is inside."""
    T = np.asarray(T_world_link, dtype=np.float64).reshape(-1, 4, 4)
    local = _link_samples(spec, pitch)
    P = np.einsum("mij,kj->mki", T[:, :3, :3], local) + T[:, None, :3, 3]  # (m, k, 3) world
    B = np.asarray(T_world_box, dtype=np.float64)
    Pb = (P - B[:3, 3]) @ B[:3, :3]  # box frame
    half = np.asarray(extents, dtype=np.float64) / 2
    outside = np.linalg.norm(np.maximum(np.abs(Pb) - half, 0.0), axis=-1)
    inside = np.minimum((np.abs(Pb) - half).max(axis=-1), 0.0)
    return (outside + inside).min(axis=1) - pitch / np.sqrt(2.0)


def box_sphere_distance(spec: ArmSpec, T_world_link, centre, radius: float) -> np.ndarray:
    """(m,) distance, metres, from each link box (frames ``T_world_link`` (m, 4, 4)) to a sphere
    (centre (3,), world frame, and radius, metres); negative inside."""
    T = np.asarray(T_world_link, dtype=np.float64).reshape(-1, 4, 4)
    c = np.asarray(centre, dtype=np.float64)
    local = np.einsum("mji,mj->mi", T[:, :3, :3], c[None, :] - T[:, :3, 3])  # R^T (c - o)
    lo = np.array([0.0, -spec.link_width / 2, -spec.link_height / 2])
    hi = np.array([spec.link_length, spec.link_width / 2, spec.link_height / 2])
    nearest = np.clip(local, lo, hi)
    return np.linalg.norm(local - nearest, axis=1) - radius


def contact_tolerance_m(spec: ArmSpec, control: ControlConfig, sim: SimConfig, sensors: SensorConfig) -> float:
    """How far, metres, a link may be from the known ball by the model at the sensed angles and
    still be touching it: the contact margin (PyBullet's default ~1 mm when
    ``SimConfig.collision_margin`` is None), plus how far the tip moves during the sensing delay
    and one step, plus the tip's position error from the encoder resolution (random errors of
    n joints, sqrt(n) counts, over the reach)."""
    margin = 1.0e-3 if sim.collision_margin is None else max(sim.collision_margin, 1.0e-4)
    reach = spec.link_length * (spec.n_links - np.arange(spec.n_links))
    tip_speed = float(np.max(sweep_speeds(spec, control) * reach))
    moving = (sensors.delay_steps + 1) * sim.timestep * tip_speed
    quant = spec.reach * sensors.angle_resolution_rad * math.sqrt(spec.n_links)
    return margin + moving + quant


def self_contact_tolerance_m(spec: ArmSpec, control: ControlConfig, sim: SimConfig, sensors: SensorConfig) -> float:
    """How close, metres, two non-adjacent bodies of the arm may be by the model at the sensed
    angles for a calibration step to count as the arm touching itself: :func:`contact_tolerance_m`
    (the model's sharp boxes are never farther apart than PyBullet's rounded ones, so its contact
    margin is a generous allowance; the motion during the sensing delay and the encoders'
    resolution apply alike), and at least the controller's own ``self_contact_tolerance``."""
    return max(contact_tolerance_m(spec, control, sim, sensors), control.self_contact_tolerance)


class _Maxima:
    """Running per-joint maxima of the contact-free signals (and how many steps of each joint's
    sweeps were seen)."""

    def __init__(self, n: int):
        self.swept = np.zeros(n)
        self.other = np.zeros(n)
        self.torque = np.zeros(n)
        self.torque_loaded = np.zeros(n)
        self.steps = np.zeros(n, dtype=int)

    def add(self, k: int, lag: float, sig, ext=None, loaded: int = -1) -> None:
        self.steps[k] += 1
        self.swept[k] = max(self.swept[k], lag)
        np.maximum(self.other, np.abs(sig), out=self.other)
        if ext is not None:
            a = np.abs(ext)
            np.maximum(self.torque_loaded[: loaded + 1], a[: loaded + 1], out=self.torque_loaded[: loaded + 1])
            np.maximum(self.torque[loaded + 1:], a[loaded + 1:], out=self.torque[loaded + 1:])


def _exceeds(band: ContactBand, k: int, lag: float, sig, ext=None, loaded: int = -1) -> bool:
    return (SweepDetector.exceeds(band, k, lag, sig) if ext is None
            else SweepDetector.exceeds(band, k, lag, sig, ext, loaded))


def _free_motion(robot, spec: ArmSpec, control: ControlConfig, bases, self_tol: float) -> tuple[_Maxima, np.ndarray]:
    """The free sweeps' maxima, and per joint the steps left out as self-contacts."""
    mx = _Maxima(spec.n_links)
    self_steps = np.zeros(spec.n_links, dtype=int)
    upper = spec.joint_upper - control.limit_margin
    speeds, torques = sweep_speeds(spec, control), sweep_torque_limits(spec, control)

    def observe(k, reading, lag, sig, ext=None, loaded=-1):
        if self_contact_pairs(spec, reading.q, self_tol):
            self_steps[k] += 1
        else:
            mx.add(k, lag, sig) if ext is None else mx.add(k, lag, sig, ext, loaded)
    for T in bases:
        for k in range(spec.n_links):
            ctl = Controller(robot, control, T, record=False)
            ctl.start()
            ctl.hold(np.zeros(spec.n_links))
            reason = sweep_joint(ctl, k, np.zeros(spec.n_links), upper, None, speeds[k], torques[k], observer=observe)
            if reason is not StopReason.LIMIT:
                raise RuntimeError(f"band calibration: joint {k}'s free sweep ended by {reason.value}, not at its limit")
    return mx, self_steps


def _impact_poses(spec: ArmSpec, centre, radius: float, planar: bool):
    r = 1.05 * radius
    if planar:
        return planar_wrap_poses(centre, r, spec.link_width, IMPACT_DIRECTIONS_PLANAR)
    return spatial_wrap_poses(centre, r, spec.link_width, IMPACT_NORMALS_3D, 1, 1)


def calibrate_band(spec: ArmSpec, control: ControlConfig = ControlConfig(), sim: SimConfig = SimConfig(),
                   sensors: SensorConfig = SensorConfig(), planar: bool = False) -> ContactBand:
    """Measure the contact band of every joint (see the module docstring).  Takes seconds to a
    minute of simulation; use :func:`cached_band`.  ``band.provenance`` records the free-motion and
    impact maxima per joint, the rounds, the false detections on the ball per round and the cost."""
    t0 = time.perf_counter()
    n = spec.n_links
    bases = [np.eye(4)] if planar else gravity_bounding_bases()
    self_tol = self_contact_tolerance_m(spec, control, sim, sensors)
    with ArmSimulation(spec, config=sim) as world:
        robot = world.robot(sensors)
        robot.reseed((1,))  # streams: (0, wrap) exploration, (1,) free motion, (2, pass, object, wrap) impacts
        free, free_self_steps = _free_motion(robot, spec, control, bases, self_tol)
    T_block = calibration_block_pose()
    objects = [  # (name, mesh, rough radius for the wrap poses, distance of link boxes to it)
        (f"sphere r={CALIBRATION_SPHERE_RADIUS_M * 1000:.0f} mm", calibration_sphere(), CALIBRATION_SPHERE_RADIUS_M,
         lambda Tl: box_sphere_distance(spec, Tl, np.zeros(3), CALIBRATION_SPHERE_RADIUS_M)),
        ("block {:.0f} x {:.0f} x {:.0f} mm".format(*(1000 * np.array(CALIBRATION_BLOCK_EXTENTS_M))), calibration_block(),
         float(np.linalg.norm(CALIBRATION_BLOCK_EXTENTS_M)) / 2,
         lambda Tl: box_box_distance(spec, Tl, T_block, CALIBRATION_BLOCK_EXTENTS_M)),
    ]
    tol = contact_tolerance_m(spec, control, sim, sensors)
    impact = _Maxima(n)

    torque = control.detector == "torque"

    def torque_bands():
        """(free, loaded) torque maxima: a joint no earlier contact loads in the free motion or an
        impact attempt bounds the free band; a loaded one, the loaded band (at least the free)."""
        t = np.maximum(free.torque, impact.torque)
        return t, np.maximum(t, impact.torque_loaded)

    def running_band() -> ContactBand:
        t, tl = torque_bands() if torque else (None, None)
        return ContactBand(swept=control.band_factor * np.maximum(free.swept, impact.swept),
                           other=control.band_factor * np.maximum(free.other, impact.other),
                           torque=None if t is None else control.band_factor * t,
                           torque_loaded=None if tl is None else control.band_factor * tl)

    # Pass 1 (measure): away from the known object no step is a contact (the object says so), and
    # its signals are recorded; near it, the detector with the bands measured so far decides.
    # Pass 2 (verify): the final bands alone decide; a detection away from the object is false.
    passes = []
    n_wraps = 0
    for name in ("measure", "verify"):
        band = running_band()
        for oi, (label, mesh, radius, distance) in enumerate(objects):
            counts = {"pass": name, "object": label, "contacts": 0, "false_detections": 0, "self_contacts": 0,
                      "self_contact_steps": 0}

            def observe(k, reading, lag, sig, ext=None, loaded=-1):
                touching_itself = bool(self_contact_pairs(spec, reading.q, self_tol))
                counts["self_contact_steps"] += touching_itself
                observe.recent.append((k, touching_itself))
                touched_lately = any(t for j, t in observe.recent if j == k)  # this sweep's last readings
                if touched_lately or distance(link_transforms(spec, reading.q, observe.T)[k:]).min() <= tol:
                    return _exceeds(running_band() if name == "measure" else band, k, lag, sig, ext, loaded)
                if name == "measure":
                    impact.add(k, lag, sig) if ext is None else impact.add(k, lag, sig, ext, loaded)
                    return False
                counts["false_detections"] += _exceeds(band, k, lag, sig, ext, loaded)
                return None

            with ArmSimulation(spec, mesh.vertices, mesh.faces, sim) as world:
                robot = world.robot(sensors)
                poses = _impact_poses(spec, np.zeros(3), radius, planar)
                n_wraps += len(poses)
                for i, pose in enumerate(poses):
                    robot.reseed((2, len(passes), oi, i))
                    observe.T = pose.T_world_base
                    observe.recent = collections.deque(maxlen=SELF_CONTACT_WINDOW_STEPS)
                    att = run_attempt(robot, pose.T_world_base, band, control, observer=observe)
                    counts["contacts"] += int(att.contact.sum())
                    counts["self_contacts"] += sum(r is StopReason.SELF for r in att.reasons)
            passes.append(counts)
    swept = np.maximum(free.swept, impact.swept)
    other = np.maximum(free.other, impact.other)
    torque_max, loaded_max = torque_bands() if torque else (None, None)
    prov = {
        "protocol_version": BAND_PROTOCOL_VERSION,
        "rule": "band_factor x the largest contact-free signal (free motion of every joint in the base orientations "
                "bounding gravity; contact-free sweep steps of attempts on the known calibration ball and block)",
        "band_factor": control.band_factor,
        "free_motion_bases": len(bases),
        "free_swept_max_rad": free.swept.tolist(), "free_other_max_rad": free.other.tolist(),
        "free_sweep_steps": free.steps.tolist(), "free_self_contact_steps": free_self_steps.tolist(),
        "impact_contact_free_steps": impact.steps.tolist(),
        "impact_swept_max_rad": impact.swept.tolist(), "impact_other_max_rad": impact.other.tolist(),
        "impact_wraps": n_wraps, "impact_passes": passes, "contact_tolerance_m": tol,
        "self_contact_tolerance_m": self_tol,
        "calibration_objects": [o[0] for o in objects],
        "wall_s": time.perf_counter() - t0,
    }
    if torque:
        prov.update({"detector": "torque", "free_torque_max_nm": free.torque.tolist(),
                     "impact_torque_max_nm": impact.torque.tolist(),
                     "impact_torque_loaded_max_nm": impact.torque_loaded.tolist()})
    return ContactBand(swept=control.band_factor * swept, other=control.band_factor * other, provenance=prov,
                       torque=None if torque_max is None else control.band_factor * torque_max,
                       torque_loaded=None if loaded_max is None else control.band_factor * loaded_max)


def _cache_dir() -> Path:
    env = os.environ.get("EXPLORE3D_CACHE_DIR")
    if env:
        return Path(env)
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "explore3d"


def band_cache_key(spec: ArmSpec, control: ControlConfig, sim: SimConfig, sensors: SensorConfig, planar: bool) -> str:
    """The hash naming a setting's cached band (everything the calibration depends on)."""
    sim_d = dataclasses.asdict(sim)
    if not sim.mass_error:  # an exact model: the key of the settings before the mass error existed
        sim_d.pop("mass_error")
        sim_d.pop("mass_seed")
    if sim.global_cfm is None:  # likewise (added after the factory bands)
        sim_d.pop("global_cfm")
    ctl_d = dataclasses.asdict(control)
    if not control.rereference_distal:  # likewise
        ctl_d.pop("rereference_distal")
    ctl_d.pop("held_load_action")  # the calibration's passes never take it (they judge every stop themselves)
    for name in ("press_force_n", "press_ramp_steps", "average_steps", "detector"):
        if ctl_d[name] == ControlConfig.__dataclass_fields__[name].default:  # likewise (added after the factory bands)
            ctl_d.pop(name)
    blob = json.dumps({"protocol": BAND_PROTOCOL_VERSION, "version": __version__, "spec": dataclasses.asdict(spec),
                       "control": ctl_d, "sim": sim_d,
                       "sensors": dataclasses.asdict(sensors), "planar": bool(planar)}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


def factory_band_path(key: str) -> Path:
    """Where the package ships the band of setting ``key`` (:func:`band_cache_key`), measured by
    ``python scripts/make_bands.py`` for the built-in arms' default settings (a real arm's factory
    calibration; the same numbers :func:`calibrate_band` gives)."""
    return Path(__file__).resolve().parent.parent / "data" / f"band-{key}.json"


#: The settings whose bands ship with the package: (arm name, planar).
FACTORY_SETTINGS = (("default", False), ("default", True), ("paper", True))


@functools.lru_cache(maxsize=16)
def cached_band(spec: ArmSpec, control: ControlConfig = ControlConfig(), sim: SimConfig = SimConfig(),
                sensors: SensorConfig = SensorConfig(), planar: bool = False) -> ContactBand:
    """:func:`calibrate_band`, computed once per setting: from memory, else from the disk cache,
    else from the factory calibration shipped with the package (the default arms' default
    settings, :func:`factory_band_path`), else measured and stored in the disk cache
    (``provenance["cache"]`` says which).  Processes that need the same uncached band at once (a
    sweep's workers on a new arm) measure it once: the others wait for it (a lock file beside the
    cached band)."""
    key = band_cache_key(spec, control, sim, sensors, planar)
    path = _cache_dir() / "bands" / f"{key}.json"
    band = _stored_band(spec, (path, factory_band_path(key)))
    if band is not None:
        return band
    with contextlib.suppress(OSError):  # a cache folder that cannot be written: measured unlocked, not stored
        path.parent.mkdir(parents=True, exist_ok=True)
    with exclusive_lock(path.with_suffix(".lock"), waiting=f"waiting for another process's band calibration ({path})"):
        band = _stored_band(spec, (path,))  # measured by another process while this one waited
        if band is not None:
            return band
        band = calibrate_band(spec, control, sim, sensors, planar)
        try:
            atomic_write_text(path, json.dumps(band.to_dict(), indent=1) + "\n")
        except OSError as exc:
            log.info("band calibration not cached (%s)", exc)
    return dataclasses.replace(band, provenance={**band.provenance, "cache": "computed"})


def _stored_band(spec: ArmSpec, paths) -> ContactBand | None:
    """The first of ``paths`` that holds a band of ``spec``'s joint count, its provenance naming
    the file; None if none does."""
    for where in paths:
        try:
            band = ContactBand.from_dict(json.loads(where.read_text()))
        except (OSError, ValueError, KeyError, TypeError):
            continue
        if len(band.swept) == spec.n_links:
            return dataclasses.replace(band, provenance={**band.provenance, "cache": str(where)})
    return None
