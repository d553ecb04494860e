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
* ``/explore3d/motion`` (``std_msgs/msg/String``), 1 ns before each motion's first reading: JSON
  ``{"wrap", "motion", "start_q", "base_T"}`` (the wrap's index, the motion's index in it, the
  rest angles, rad, and the (4, 4) base pose, exact);
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
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import CompressionFormat, CompressionMode, Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

from explore3d.app.offline import RECORDING_FORMAT_VERSION, Recording, recording_from_dict
from explore3d.arm.spec import ArmSpec
from explore3d.core.io import json_text
from explore3d.robot.interface import RobotLog

__all__ = ["STORAGES", "TOPICS", "BagTopics", "read_bag", "read_joint_bag", "write_bag"]

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


@dataclass(frozen=True)
class BagTopics:
    """Where another controller's bag keeps what a reconstruction reads (:func:`read_joint_bag`).

    Attributes:
        joint_states: ``sensor_msgs/msg/JointState``: angles (rad), velocities (rad/s), motor
            torques (``effort``, N m).
        references: ``sensor_msgs/msg/JointState`` whose ``position`` holds the position
            references (rad) the controller sent.
        base_pose: ``geometry_msgs/msg/PoseStamped``, the arm's base in the world frame (m), one
            message at the start of each motion.
        joint_names: the arm's joints in the order of its chain (None: ``joint0`` ...).
    """

    joint_states: str = "/joint_states"
    references: str = "/explore3d/joint_command"
    base_pose: str = "/explore3d/base_pose"
    joint_names: tuple | None = None


def _order(names, want, topic, path):
    """Indices of ``want`` in a message's ``names`` (a message without names is in chain order)."""
    if not len(names):
        return None
    try:
        return [list(names).index(w) for w in want]
    except ValueError:
        raise ValueError(f"{path}: {topic} names the joints {list(names)[:4]}...; the arm's are {list(want)[:4]}... "
                         "(give their order with joint_names / --joint-names)") from None


def read_joint_bag(path, spec, topics: BagTopics = BagTopics(), gravity=(0.0, 0.0, -9.81)) -> tuple:
    """Robot logs from a ROS 1 or ROS 2 bag recorded by any controller: one
    :class:`~explore3d.robot.interface.RobotLog` per base-pose message (a motion, taken as a wrap),
    its readings from ``topics.joint_states`` and, for each, the last reference sent before it
    (``topics.references``).  What the live controller's replay would also need (torque limits,
    feed-forward) is not read: read the logs with
    :func:`explore3d.strategy.readings.exploration_from_readings`.  ``spec``: the arm;
    ``gravity`` (3,) m/s^2, world frame.  The control period is the median step between readings.
    ValueError naming a missing topic, joint names that are not the arm's, too few readings,
    NaN readings or stamps that go back."""

    path = Path(path)
    if not path.exists():
        raise ValueError(f"{path} does not exist; give a ROS 1 bag file or a ROS 2 bag folder")
    names = list(topics.joint_names) if topics.joint_names else joint_names(spec.n_links)
    if len(names) != spec.n_links:
        raise ValueError(f"joint_names lists {len(names)} joints; the arm has {spec.n_links}")
    poses, refs, readings = [], [], []
    try:
        with AnyReader([path], default_typestore=_TYPESTORE) as r:
            have = {c.topic for c in r.connections}
            missing = [t for t in (topics.joint_states, topics.references, topics.base_pose) if t not in have]
            if missing:
                raise ValueError(f"{path} has no topic {missing[0]!r} (its topics: {sorted(have)}); name the "
                                 "topics with --joint-states, --references, --base-pose")
            conns = [c for c in r.connections if c.topic in (topics.joint_states, topics.references, topics.base_pose)]
            for conn, ns, raw in r.messages(connections=conns):
                msg = r.deserialize(raw, conn.msgtype)
                if conn.topic == topics.base_pose:
                    q = msg.pose.orientation
                    T = np.eye(4)
                    T[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
                    T[:3, 3] = [msg.pose.position.x, msg.pose.position.y, msg.pose.position.z]
                    poses.append((ns, T))
                elif conn.topic == topics.references:
                    idx = _order(msg.name, names, conn.topic, path)
                    p = np.asarray(msg.position, float)
                    refs.append((ns, p if idx is None else p[idx]))
                else:
                    if readings and ns < readings[-1][0]:
                        raise ValueError(f"{path}: {conn.topic} goes back in time at {ns} ns; sort the bag")
                    idx = _order(msg.name, names, conn.topic, path)
                    arr = [np.asarray(getattr(msg, f), float) for f in ("position", "velocity", "effort")]
                    if idx is not None:
                        arr = [a[idx] for a in arr]
                    if any(len(a) != spec.n_links for a in arr):
                        raise ValueError(f"{path}: {conn.topic} at {ns} ns has {[len(a) for a in arr]} values; the "
                                         f"arm has {spec.n_links} joints (position, velocity and effort needed)")
                    readings.append((ns, *arr))
    except ValueError:
        raise
    except Exception as exc:  # rosbags' own errors
        raise ValueError(f"cannot read the bag {path} ({type(exc).__name__}: {exc})") from None
    # each reading with the last reference sent at or before its stamp, within the motion whose
    # base pose came last before it
    ref_ns = np.array([x[0] for x in refs], dtype=np.int64)
    pose_ns = np.array([x[0] for x in poses], dtype=np.int64)
    motions, rows = [], []
    for ns, q, dq, tau in readings:
        ri = int(np.searchsorted(ref_ns, ns, side="right")) - 1
        pi = int(np.searchsorted(pose_ns, ns, side="right")) - 1
        if ri < 0 or pi < 0:
            continue  # before the first reference or the first base pose
        if not motions or motions[-1][2] != pi:
            motions.append((poses[pi][1], len(rows), pi))
        rows.append((ns, q, dq, tau, refs[ri][1]))
    motions = [(T, first) for T, first, _ in motions]
    stamps = np.array([r[0] for r in rows], dtype=np.int64)
    dt = float(np.median(np.diff(stamps))) * 1e-9
    logs = []
    bounds = [m[1] for m in motions] + [len(rows)]
    for (T, first), end in zip(motions, bounds[1:]):
        if end - first < 2:
            continue
        part = rows[first:end]
        q, dq, tau, q_ref = (np.array([r[i] for r in part]) for i in (1, 2, 3, 4))
        if not all(np.isfinite(a).all() for a in (q, dq, tau, q_ref)):
            raise ValueError(f"{path}: a reading or reference after the base pose at {stamps[first]} ns is NaN or "
                             "infinite")
        zeros = np.zeros_like(q)
        logs.append(RobotLog(spec=spec, dt=dt, gravity=np.asarray(gravity, float), base_T=T[None],
                             start_q=q[:1].copy(), start_index=np.array([0]),
                             t_s=(stamps[first:end] - stamps[first]) * 1e-9, q=q, dq=dq, tau=tau, q_ref=q_ref,
                             dq_ref=zeros, torque_limit=np.full_like(q, np.inf), tau_ff=zeros))
    return tuple(logs)
