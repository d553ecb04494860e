"""A run's robot logs on disk, and its estimate rebuilt from them with no world (issue 26).

A *recording* is a folder (``explore3d run ... --record DIR``, :func:`write_recording`):

* ``wrap_0000.npz``, ``wrap_0001.npz``, ...: one :class:`~explore3d.robot.interface.RobotLog`
  per wrap, in wrap order (docs/robot-interface.md gives the layout): the base pose of every
  motion, and at every control step the command sent and the joint angles, velocities and motor
  torques read back;
* ``recording.json``, written last: ``format_version``, ``arm`` (the
  :class:`~explore3d.arm.spec.ArmSpec` fields), ``explore`` (the
  :class:`~explore3d.strategy.explore.ExploreConfig`, :meth:`~ExploreConfig.to_dict`), ``band``
  (the contact band the run used, :meth:`~explore3d.feeling.detect.ContactBand.to_dict`), the
  rough bound ``centre_m`` and ``radius_m``, ``table_z_m`` (the table height the robot was told,
  or null), the inverse hull's ``a`` and ``method``, and ``wraps`` (the log files in order).

Everything in it is what the robot knew: its own model, its commands and readings, the known
base poses, the rough bound and the table height.  :func:`reconstruct_recording` replays the logs
through the same controller (:class:`~explore3d.robot.interface.LogWorkcell`: every command is
checked against the recorded one, so the controller takes the recorded decisions), localises the
contacts from the recorded readings, sweeps the free space from the recorded angles and builds
the estimate as the run did (:func:`explore3d.app.pipeline.estimate_exploration`): the same
arithmetic, so the same estimate.  A log recorded by another controller does not replay
(:class:`~explore3d.robot.interface.LogMismatchError` names the first command that differs); with
``replay=False`` the logs are only read, with no controller in the loop
(:mod:`explore3d.strategy.readings`: sweeps, detections and settled readings found in the
recorded references and readings), which any controller's logs allow.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from explore3d.app.pipeline import estimate_exploration
from explore3d.arm.spec import ArmSpec
from explore3d.core.io import atomic_write_text, json_text
from explore3d.feeling.detect import ContactBand
from explore3d.robot.interface import LogWorkcell, RobotLog
from explore3d.strategy.explore import Exploration, ExploreConfig, explore_robots
from explore3d.strategy.readings import exploration_from_readings

__all__ = ["RECORDING_FORMAT_VERSION", "RECORDING_NAME", "Recording", "read_recording", "reconstruct_recording",
           "recording_dict", "recording_from_dict", "write_recording"]

#: Version of the recording folder's layout (module docstring).
RECORDING_FORMAT_VERSION = 1

#: The file that makes a folder a recording; written last.
RECORDING_NAME = "recording.json"


@dataclass(frozen=True)
class Recording:
    """What a recording folder holds (module docstring): the arm, how it explored, its contact
    band, the rough bound (``centre`` (3,) world frame, m; ``radius`` m), the table height it was
    told (world z, m, or None), the inverse hull's ``a`` and ``method``, and one
    :class:`~explore3d.robot.interface.RobotLog` per wrap."""

    spec: ArmSpec
    config: ExploreConfig
    band: ContactBand
    centre: np.ndarray
    radius: float
    table_z: float | None
    a: float
    method: str
    logs: tuple


def recording_dict(ex: Exploration, centre, radius: float, a: float, method: str) -> dict:
    """The ``recording.json`` of ``ex`` (module docstring): ``centre`` (3,), ``radius``: the rough
    bound the robot was told (world frame, m); ``a``, ``method``: the inverse hull's."""
    if ex.logs is None:
        raise ValueError("the exploration kept no robot logs: explore with ExploreConfig(record=True) "
                         "(explore3d run --record DIR) to write a recording")
    return {"format_version": RECORDING_FORMAT_VERSION, "arm": asdict(ex.spec), "explore": ex.config.to_dict(),
            "band": ex.band.to_dict(), "centre_m": [float(x) for x in np.asarray(centre, float)],
            "radius_m": float(radius), "table_z_m": None if ex.table_z is None else float(ex.table_z),
            "a": float(a), "method": str(method), "wraps": [f"wrap_{i:04d}.npz" for i in range(len(ex.logs))]}


def write_recording(ex: Exploration, folder, centre, radius: float, a: float, method: str) -> Path:
    """Write the recording of ``ex`` (explored with ``ExploreConfig(record=True)``) into
    ``folder`` (created): the wraps' logs, then ``recording.json`` (:func:`recording_dict`; the
    arguments are its).  A recording already in ``folder`` is replaced (its ``recording.json``
    goes first, so a folder never lists logs of two runs).  Returns the path of
    ``recording.json``.  The same as a ROS 2 bag: :func:`explore3d.app.rosbag.write_bag`."""
    meta = recording_dict(ex, centre, radius, a, method)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / RECORDING_NAME).unlink(missing_ok=True)
    for name, log in zip(meta["wraps"], ex.logs):
        log.save(folder / name)
    for stale in folder.glob("wrap_*.npz"):  # a longer earlier recording's
        if stale.name not in meta["wraps"]:
            stale.unlink()
    return atomic_write_text(folder / RECORDING_NAME, json_text(meta))


def read_recording(folder) -> Recording:
    """Read a recording folder (module docstring); ValueError naming what is missing or wrong."""
    folder = Path(folder)
    path = folder / RECORDING_NAME
    if not path.is_file():
        raise ValueError(f"{folder} holds no {RECORDING_NAME}: give a folder 'explore3d run ... --record DIR' wrote")
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ValueError(f"cannot read {path} ({exc}); write the recording again") from None
    if meta.get("format_version") != RECORDING_FORMAT_VERSION:
        raise ValueError(f"{path} has format_version {meta.get('format_version')!r}; this explore3d reads "
                         f"{RECORDING_FORMAT_VERSION}")
    _check_keys(meta, path)
    return recording_from_dict(meta, tuple(RobotLog.load(folder / name) for name in meta["wraps"]), folder)


def _check_keys(meta: dict, where) -> None:
    missing = [k for k in ("arm", "explore", "band", "centre_m", "radius_m", "table_z_m", "a", "method", "wraps")
               if k not in meta]
    if missing:
        raise ValueError(f"{where} lacks {missing}; write the recording again")
    if not meta["wraps"]:
        raise ValueError(f"{where} lists no wrap logs; record a run that ran at least one wrap")


def recording_from_dict(meta: dict, logs, where="the recording") -> Recording:
    """The :class:`Recording` of a ``recording.json`` dict ``meta`` and its wraps' ``logs`` (one
    :class:`RobotLog` each, in order); ValueError when they do not fit together."""
    _check_keys(meta, where)
    spec = ArmSpec(**meta["arm"])
    if len(logs) != len(meta["wraps"]):
        raise ValueError(f"{where} lists {len(meta['wraps'])} wraps but holds {len(logs)} logs")
    for name, log in zip(meta["wraps"], logs):
        if log.spec != spec:
            raise ValueError(f"{name} in {where} is a log of another arm ({log.spec.name!r}) than the recording's "
                             f"({spec.name!r}); keep one recording per folder")
    return Recording(spec=spec, config=ExploreConfig.from_dict(meta["explore"]), band=ContactBand.from_dict(meta["band"]),
                     centre=np.asarray(meta["centre_m"], float), radius=float(meta["radius_m"]),
                     table_z=meta["table_z_m"], a=float(meta["a"]), method=str(meta["method"]), logs=tuple(logs))


def reconstruct_recording(rec: Recording, jobs: int | None = 1, progress=None, replay: bool = True):
    """The estimate of a recorded run, rebuilt from its logs alone (module docstring).

    Args:
        rec: a :class:`Recording` (:func:`read_recording`).
        jobs: worker processes replaying the wraps (results do not depend on it).
        progress: as :func:`~explore3d.strategy.explore.explore_robots`'s.
        replay: replay the controller against the logs (exact for explore3d's own logs); False:
            read the logs with no controller in the loop
            (:func:`explore3d.strategy.readings.exploration_from_readings`: any controller's logs,
            the wraps as recorded, no probes planned).

    Returns:
        ``(exploration, estimate)``: the replayed :class:`Exploration` (carried back when the
        run registered a moved object) and the estimate (trimesh 3D, shapely Polygon planar),
        world frame, metres.

    Raises:
        LogMismatchError: the controller asked for a command the logs do not hold.
        ReconstructionError: the contacts gave no hull.
    """
    config = replace(rec.config, jobs=jobs, record=False)
    if replay:
        persistent = not config.scene.ideal and config.scene.persistent
        ex = explore_robots(LogWorkcell(rec.logs), rec.spec, config, rec.band, rec.centre, rec.radius, progress,
                            table_z=rec.table_z, persistent=persistent)
    else:
        ex = exploration_from_readings(rec.logs, rec.spec, config, rec.band, rec.centre, rec.radius, rec.table_z)
    ex, _, _, _, est = estimate_exploration(ex, rec.centre, rec.radius, rec.a, rec.method)
    return ex, est
