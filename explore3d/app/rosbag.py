"""A run's recording as a ROS 2 bag, written and read with the pure-Python ``rosbags`` package
(issue 26).

``explore3d run ... --record DIR`` writes ``DIR/bag`` beside the ``.npz`` logs
(:mod:`explore3d.app.offline`); ``explore3d reconstruct --bag DIR/bag`` rebuilds the run's
estimate from the bag alone.  Storage: sqlite3 (rosbag2 format version 8) by default, or MCAP.
Topics (n joints, named ``joint0`` ... as in the arm's URDF):

* ``/joint_states`` (``sensor_msgs/msg/JointState``), one per control step: ``position`` the joint
  angles (rad), ``velocity`` (rad/s), ``effort`` the motor torques (N m, feed-forward included);
* ``/explore3d/joint_command`` (``sensor_msgs/msg/JointState``, no names: the joints in
  ``/joint_states``' order), same stamps: the command sent before that reading: ``position`` the references (rad), ``velocity`` the velocity feed-forward
  (rad/s), ``effort`` the feed-forward torque (N m);
* ``/explore3d/torque_limit`` (``sensor_msgs/msg/JointState``, no names), same stamps: ``effort`` the
  motors' torque limits (N m);
* ``/explore3d/base_pose`` (``geometry_msgs/msg/PoseStamped``, frame ``world``), 1 ns before each
  motion's first reading: ``T_world_base`` (for ROS tools);
* ``/explore3d/motion`` (``std_msgs/msg/String``), 1 ns before each motion's first reading: JSON ``{"wrap", "motion", "start_q", "base_T"}`` (the wrap's index, the motion's index
  in it, the rest angles, rad, and the (4, 4) base pose, exact);
* ``/explore3d/recording`` (``std_msgs/msg/String``), first: the recording's ``recording.json``
  (the arm, the settings, the band, the rough bound, the table height) plus ``dt_s`` and
  ``gravity_m_s2``.

Stamps: each motion starts one control period after the previous one ended; its k-th reading is
stamped ``start + round(k dt 1e9)`` ns.  Readings carry float64 arrays, so the bag holds the
``.npz`` logs' numbers exactly and the estimate rebuilt from it is the run's.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import CompressionFormat, CompressionMode, Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from explore3d.app.offline import RECORDING_FORMAT_VERSION, Recording, recording_from_dict
from explore3d.core.io import json_text
from explore3d.robot.interface import RobotLog

__all__ = ["STORAGES", "TOPICS", "read_bag", "write_bag"]

#: The bag's topics and their message types (module docstring).
TOPICS = {"/explore3d/recording": "std_msgs/msg/String", "/explore3d/motion": "std_msgs/msg/String",
          "/explore3d/base_pose": "geometry_msgs/msg/PoseStamped", "/joint_states": "sensor_msgs/msg/JointState",
          "/explore3d/joint_command": "sensor_msgs/msg/JointState",
          "/explore3d/torque_limit": "sensor_msgs/msg/JointState"}

#: Storage plugins :func:`write_bag` offers.
STORAGES = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}

_TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)


def joint_names(n: int) -> list[str]:
    """The names of an n-joint arm's joints, as its URDF (:func:`explore3d.arm.urdf.write_arm_urdf`)
    and the bag's ``/joint_states`` give them."""
    return [f"joint{i}" for i in range(n)]


def _stamp(ns: int):
    Time = _TYPESTORE.types["builtin_interfaces/msg/Time"]
    return Time(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))


def _joint_state(ns: int, names, position, velocity, effort):
    T = _TYPESTORE.types
    return T["sensor_msgs/msg/JointState"](
        header=T["std_msgs/msg/Header"](stamp=_stamp(ns), frame_id=""), name=list(names),
        position=np.asarray(position, dtype=np.float64), velocity=np.asarray(velocity, dtype=np.float64),
        effort=np.asarray(effort, dtype=np.float64))


def _pose(ns: int, T_world_base):
    from scipy.spatial.transform import Rotation  # start-up: kept out of the module's import

    T = _TYPESTORE.types
    x, y, z, w = Rotation.from_matrix(np.asarray(T_world_base, float)[:3, :3]).as_quat()
    p = np.asarray(T_world_base, float)[:3, 3]
    return T["geometry_msgs/msg/PoseStamped"](
        header=T["std_msgs/msg/Header"](stamp=_stamp(ns), frame_id="world"),
        pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]),
                                         orientation=T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)))


def _string(text: str):
    return _TYPESTORE.types["std_msgs/msg/String"](data=text)


def write_bag(recording: dict, logs, path, storage: str = "sqlite3", compress: bool = True) -> Path:
    """Write a recording (``recording``: the dict of its ``recording.json``,
    :func:`explore3d.app.offline.recording_dict`; ``logs``: one
    :class:`~explore3d.robot.interface.RobotLog` per wrap) as a ROS 2 bag folder ``path``
    (module docstring); a bag already at ``path`` is replaced, anything else there is refused.
    ``compress``: the bag's file compressed with zstd (rosbag2's file compression, which ROS 2's
    own tools and ``rosbags`` read; about 10x smaller).  Returns ``path``."""
    if storage not in STORAGES:
        raise ValueError(f"storage must be one of {sorted(STORAGES)}; got {storage!r}")
    logs = list(logs)
    if not logs:
        raise ValueError("a bag needs at least one wrap's log")
    path = Path(path)
    if path.exists():
        if not (path.is_dir() and (path / "metadata.yaml").is_file()):
            raise ValueError(f"{path} exists and is not a ROS 2 bag: give the bag a path of its own")
        shutil.rmtree(path)  # the replaced recording's bag
    dt = float(logs[0].dt)
    meta = {**recording, "dt_s": dt, "gravity_m_s2": [float(g) for g in logs[0].gravity]}
    names = joint_names(logs[0].spec.n_links)
    ser = _TYPESTORE.serialize_cdr
    w = Writer(path, version=8, storage_plugin=STORAGES[storage])
    if compress:
        w.set_compression(CompressionMode.FILE, CompressionFormat.ZSTD)
    with w:
        conns = {topic: w.add_connection(topic, kind, typestore=_TYPESTORE) for topic, kind in TOPICS.items()}

        def put(topic, ns, msg):
            w.write(conns[topic], ns, ser(msg, TOPICS[topic]))

        put("/explore3d/recording", 0, _string(json_text(meta)))
        ns = 0
        step_ns = int(round(dt * 1e9))
        for wrap, log in enumerate(logs):
            ends = list(log.start_index[1:]) + [log.n_steps]
            for m, (first, end) in enumerate(zip(log.start_index, ends)):
                ns += step_ns
                start = ns
                motion = {"wrap": wrap, "motion": m, "start_q": log.start_q[m].tolist(),
                          "base_T": log.base_T[m].tolist()}
                put("/explore3d/motion", start - 1, _string(json.dumps(motion)))  # before its first reading
                put("/explore3d/base_pose", start - 1, _pose(start - 1, log.base_T[m]))
                for k, i in enumerate(range(int(first), int(end))):
                    ns = start + int(round(k * dt * 1e9))
                    put("/joint_states", ns, _joint_state(ns, names, log.q[i], log.dq[i], log.tau[i]))
                    put("/explore3d/joint_command", ns,
                        _joint_state(ns, (), log.q_ref[i], log.dq_ref[i], log.tau_ff[i]))
                    put("/explore3d/torque_limit", ns, _joint_state(ns, (), (), (), log.torque_limit[i]))
    return path


def read_bag(path) -> Recording:
    """The :class:`~explore3d.app.offline.Recording` a bag written by :func:`write_bag` holds.
    ValueError naming a missing topic, a bag of another layout or a broken reading."""
    path = Path(path)
    if not path.is_dir() or not (path / "metadata.yaml").is_file():
        raise ValueError(f"{path} is not a ROS 2 bag folder (no metadata.yaml): give the bag folder "
                         "'explore3d run ... --record DIR' wrote (DIR/bag)")
    de = _TYPESTORE.deserialize_cdr
    meta, motions, steps = None, [], []

    def names(meta):
        if meta is None:
            raise ValueError(f"{path}: readings come before the /explore3d/recording message")
        return joint_names(meta["arm"]["n_links"])

    try:
        with Reader(path) as r:
            have = {c.topic for c in r.connections}
            missing = sorted(set(TOPICS) - have)
            if missing:
                raise ValueError(f"{path} lacks the topic(s) {missing}; it was not written by explore3d's write_bag")
            conns = [c for c in r.connections if c.topic in TOPICS]
            current = {}
            for conn, ns, raw in r.messages(connections=conns):
                msg = de(raw, conn.msgtype)
                if conn.topic == "/explore3d/recording":
                    meta = json.loads(msg.data)
                elif conn.topic == "/explore3d/motion":
                    motions.append(json.loads(msg.data))
                    current = {}
                elif conn.topic in ("/joint_states", "/explore3d/joint_command", "/explore3d/torque_limit"):
                    if not motions:
                        raise ValueError(f"{path}: a reading at {ns} ns comes before any motion starts")
                    if conn.topic == "/joint_states" and list(msg.name) != names(meta):
                        raise ValueError(f"{path}: /joint_states at {ns} ns names the joints {list(msg.name)[:4]}...; "
                                         f"the recording's arm has {names(meta)[:4]}... ({len(names(meta))} joints): "
                                         "the bag is not of this arm")
                    row = current.setdefault(ns, {"motion": len(motions) - 1})
                    row[conn.topic] = msg
                    if len(row) == 4:  # the three topics of one step
                        steps.append(row)
    except ValueError:
        raise
    except Exception as exc:  # rosbags' own errors (a damaged database, an unknown message type)
        raise ValueError(f"cannot read the bag {path} ({type(exc).__name__}: {exc})") from None
    if meta is None:
        raise ValueError(f"{path} has no /explore3d/recording message; it was not written by explore3d's write_bag")
    if meta.get("format_version") != RECORDING_FORMAT_VERSION:
        raise ValueError(f"{path} holds a recording of format_version {meta.get('format_version')!r}; this "
                         f"explore3d reads {RECORDING_FORMAT_VERSION}")
    return recording_from_dict(meta, _logs(meta, motions, steps, path))


def _logs(meta: dict, motions: list, steps: list, path: Path) -> tuple:
    from explore3d.arm.spec import ArmSpec  # start-up: kept out of the module's import

    spec = ArmSpec(**meta["arm"])
    dt, gravity = float(meta["dt_s"]), np.asarray(meta["gravity_m_s2"], float)
    n_wraps = len(meta["wraps"])
    per_motion = [[] for _ in motions]
    for row in steps:
        per_motion[row["motion"]].append(row)
    logs = []
    for wrap in range(n_wraps):
        ms = [i for i, m in enumerate(motions) if m["wrap"] == wrap]
        if not ms:
            raise ValueError(f"{path} holds no motion of wrap {wrap} of the {n_wraps} its recording lists")
        rows = [row for i in ms for row in per_motion[i]]
        if any(not per_motion[i] for i in ms):
            raise ValueError(f"{path}: a motion of wrap {wrap} has no readings")
        start_index = np.cumsum([0] + [len(per_motion[i]) for i in ms[:-1]])
        t_s = np.concatenate([np.arange(len(per_motion[i])) * dt for i in ms])

        def col(topic, field):
            return np.array([getattr(row[topic], field) for row in rows], dtype=np.float64)

        log = RobotLog(spec=spec, dt=dt, gravity=gravity, base_T=np.array([motions[i]["base_T"] for i in ms]),
                       start_q=np.array([motions[i]["start_q"] for i in ms]), start_index=start_index.astype(np.int64),
                       t_s=t_s, q=col("/joint_states", "position"), dq=col("/joint_states", "velocity"),
                       tau=col("/joint_states", "effort"), q_ref=col("/explore3d/joint_command", "position"),
                       dq_ref=col("/explore3d/joint_command", "velocity"),
                       tau_ff=col("/explore3d/joint_command", "effort"),
                       torque_limit=col("/explore3d/torque_limit", "effort"))
        try:
            log.check()
        except ValueError as exc:
            raise ValueError(f"{path}, wrap {wrap}: {exc} (the joint names or counts do not match the arm)") from None
        if not all(np.isfinite(getattr(log, k)).all() for k in ("q", "dq", "tau", "q_ref", "dq_ref", "tau_ff")):
            raise ValueError(f"{path}, wrap {wrap}: a reading or command is NaN or infinite")
        logs.append(log)
    return tuple(logs)
