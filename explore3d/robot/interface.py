"""The robot interface: the one door through which the controller, the detector and every
estimator read the arm.

A blind arm knows what its servos report (joint angles and velocities, the motor torques they
apply), what it commanded (references, velocity feed-forward, torque limits, feed-forward
torques), its own model (:class:`~explore3d.arm.spec.ArmSpec`: geometry, masses; forward kinematics and
Jacobians in :mod:`explore3d.arm.kinematics`), the known transforms that move its base, and gravity.
:class:`Robot` exposes exactly that and nothing else: no simulator client, no contacts, no object.

Implementations:

* :class:`explore3d.world.sim.SimRobot`: the PyBullet arm seen through :mod:`explore3d.robot.sensing`;
* :class:`LogRobot`: a recorded :class:`RobotLog` played back (a simulated run, or a real
  robot's log in the same documented format);
* :class:`RecordingRobot`: wraps any robot and records what passes through the door (a
  :class:`ForwardingRobot`, the base of every observer of the traffic).

Frames: ``T_world_base`` (4, 4) maps base coordinates to world coordinates (see
:mod:`explore3d.arm.spec`).  Angles rad, velocities rad/s, torques N m, times s.
"""
from __future__ import annotations

import abc
import io as _io
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from explore3d.arm.spec import ArmSpec
from explore3d.core.io import atomic_write_bytes
from explore3d.robot.sensing import SensorConfig

__all__ = [
    "JointCommand", "JointReading", "Robot", "RobotLog", "ForwardingRobot", "RecordingRobot", "LogRobot",
    "LogMismatchError",
    "LOG_FORMAT_VERSION", "Workcell", "LogWorkcell",
]


@dataclass(frozen=True)
class JointCommand:
    """What the controller sends every control step (n = number of joints).

    Attributes:
        q_ref: (n,) position references, rad.
        dq_ref: (n,) velocity feed-forward, rad/s.
        torque_limit: (n,) the motors' torque limits, N m.
        tau_ff: (n,) feed-forward motor torque, N m (e.g. gravity compensation from the model);
            added to what the position loop applies.
    """

    q_ref: np.ndarray
    dq_ref: np.ndarray
    torque_limit: np.ndarray
    tau_ff: np.ndarray


@dataclass(frozen=True)
class JointReading:
    """What the servos report at one control step.

    Attributes:
        t_s: time since the start of the motion, s.
        q: (n,) joint angles, rad.
        dq: (n,) joint velocities, rad/s.
        tau: (n,) motor torques the servos apply (their current), feed-forward included, N m.
    """

    t_s: float
    q: np.ndarray
    dq: np.ndarray
    tau: np.ndarray


class Robot(abc.ABC):
    """A blind arm: commands in, joint readings out.

    Attributes (read-only):
        spec: the arm's own model (geometry, masses, joint limits, motor torque limits).
        dt: control period, s.
        gravity: (3,) gravity vector, world frame, m/s^2 (a fact the robot is given).
    """

    spec: ArmSpec
    dt: float
    gravity: np.ndarray

    @property
    @abc.abstractmethod
    def base_pose(self) -> np.ndarray:
        """(4, 4) ``T_world_base`` of the current motion (a known transform)."""

    @abc.abstractmethod
    def start(self, T_world_base, q0) -> JointReading:
        """Begin a motion: the base at the known pose ``T_world_base`` (4, 4), the joints at rest at
        ``q0`` (n,), rad, references ``q0``; return the first reading."""

    @abc.abstractmethod
    def step(self, command: JointCommand) -> JointReading:
        """Send ``command``, advance one control period, return the reading."""


class Workcell(abc.ABC):
    """Where a strategy's robots come from: one arm in one world (a simulated world, a real cell).

    A strategy is handed a *factory* of workcells, any picklable callable without arguments that
    opens one (worker processes each open their own; e.g. :class:`explore3d.world.explore.SimWorkcells`),
    and runs every wrap on :meth:`robot`; it never sees what is behind.  A workcell is a context
    manager (:meth:`close` on exit).

    Attributes (read-only):
        spec: the arm's own model.
        steps: physics steps taken so far (times the timestep: simulated time, s).
    """

    spec: ArmSpec
    steps: int

    @abc.abstractmethod
    def robot(self, sensors: SensorConfig = SensorConfig(), wrap: int | None = None) -> Robot:
        """The :class:`Robot` of this cell for wrap number ``wrap`` of an exploration (None: not
        for a wrap), its servos read as ``sensors`` says (a simulated cell's sensor model; a real
        one may ignore it).  A simulated cell seeds its sensor noise with the wrap's number, so
        results do not depend on the order of the wraps or the number of processes; a
        :class:`LogWorkcell` plays that wrap's log."""

    def close(self) -> None:
        """Release the cell (a simulator's client, a connection)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def make_command(spec: ArmSpec, q_ref, dq_ref=None, torque_limit=None, tau_ff=None) -> JointCommand:
    """A :class:`JointCommand` with defaults: no feed-forward, the arm's full torque limits."""
    n = spec.n_links
    z = np.zeros(n)
    return JointCommand(
        q_ref=np.asarray(q_ref, dtype=np.float64),
        dq_ref=z if dq_ref is None else np.asarray(dq_ref, dtype=np.float64),
        torque_limit=np.asarray(spec.joint_torques() if torque_limit is None else torque_limit, dtype=np.float64),
        tau_ff=z if tau_ff is None else np.asarray(tau_ff, dtype=np.float64),
    )


#: Version of the :class:`RobotLog` file format.
LOG_FORMAT_VERSION = 1


@dataclass(frozen=True)
class RobotLog:
    """A recorded run of a robot: every motion's base pose and every control step.

    The file (:meth:`save`, :meth:`load`) is a NumPy ``.npz`` archive holding these arrays
    (T steps, S motions, n joints) and ``meta``, a JSON string with ``format_version``, ``spec``
    (the :class:`~explore3d.arm.spec.ArmSpec` fields), ``dt_s`` and ``gravity_m_s2``; a real robot's log
    written in this layout plays back through :class:`LogRobot`.

    Attributes:
        spec: the arm.
        dt: control period, s.
        gravity: (3,) m/s^2, world frame.
        base_T: (S, 4, 4) ``T_world_base`` of each motion.
        start_q: (S, n) rest angles commanded at each motion's start, rad.
        start_index: (S,) index into the step arrays of each motion's first reading.
        t_s: (T,) time since the motion's start, s (the start reading has t = 0).
        q, dq, tau: (T, n) readings: rad, rad/s, N m.
        q_ref, dq_ref, torque_limit, tau_ff: (T, n) the command sent before each reading (the
            start reading's command is the rest command: q_ref = start_q, the rest 0 / full limits).
    """

    spec: ArmSpec
    dt: float
    gravity: np.ndarray
    base_T: np.ndarray
    start_q: np.ndarray
    start_index: np.ndarray
    t_s: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    tau: np.ndarray
    q_ref: np.ndarray
    dq_ref: np.ndarray
    torque_limit: np.ndarray
    tau_ff: np.ndarray

    _ARRAYS = ("base_T", "start_q", "start_index", "t_s", "q", "dq", "tau", "q_ref", "dq_ref", "torque_limit",
               "tau_ff")

    @property
    def n_motions(self) -> int:
        return len(self.base_T)

    @property
    def n_steps(self) -> int:
        return len(self.t_s)

    def reading(self, i: int) -> JointReading:
        """Row ``i``'s :class:`JointReading` (copies of its angles, velocities and torques)."""
        return JointReading(t_s=float(self.t_s[i]), q=self.q[i].copy(), dq=self.dq[i].copy(), tau=self.tau[i].copy())

    def save(self, path) -> Path:
        """Write the log to ``path`` (.npz) atomically; returns the path."""
        path = Path(path)
        meta = {"format_version": LOG_FORMAT_VERSION, "spec": asdict(self.spec), "dt_s": self.dt,
                "gravity_m_s2": [float(g) for g in self.gravity]}
        buf = _io.BytesIO()
        np.savez_compressed(buf, meta=np.array(json.dumps(meta)), **{k: getattr(self, k) for k in self._ARRAYS})
        atomic_write_bytes(path, buf.getvalue())
        return path

    @classmethod
    def load(cls, path) -> "RobotLog":
        """Read a log written by :meth:`save` (or by a real robot in the same layout)."""
        path = Path(path)
        if not path.is_file():
            raise ValueError(f"robot log {str(path)!r} does not exist; check the path")
        try:
            with np.load(path, allow_pickle=False) as z:
                data = {k: z[k] for k in z.files}
        except (OSError, ValueError) as exc:
            raise ValueError(f"cannot read robot log {str(path)!r} ({exc}); it must be an .npz written by RobotLog.save") from None
        missing = [k for k in ("meta", *cls._ARRAYS) if k not in data]
        if missing:
            raise ValueError(f"robot log {str(path)!r} lacks {missing}; see explore3d.robot.interface.RobotLog for the layout")
        meta = json.loads(str(data.pop("meta")))
        if meta.get("format_version") != LOG_FORMAT_VERSION:
            raise ValueError(f"robot log {str(path)!r} has format_version {meta.get('format_version')!r}; "
                             f"this explore3d reads {LOG_FORMAT_VERSION}")
        log = cls(spec=ArmSpec(**meta["spec"]), dt=float(meta["dt_s"]), gravity=np.asarray(meta["gravity_m_s2"], float),
                  **data)
        log.check()
        return log

    def check(self) -> None:
        """Raise ValueError if the arrays' shapes do not fit together."""
        n, T, S = self.spec.n_links, len(self.t_s), len(self.base_T)
        want = {"base_T": (S, 4, 4), "start_q": (S, n), "start_index": (S,), "t_s": (T,)}
        want.update({k: (T, n) for k in ("q", "dq", "tau", "q_ref", "dq_ref", "torque_limit", "tau_ff")})
        for k, shape in want.items():
            got = np.shape(getattr(self, k))
            if got != shape:
                raise ValueError(f"robot log: {k} must have shape {shape}; got {got}")


class ForwardingRobot(Robot):
    """Wraps a robot and passes everything through unchanged; subclasses observe the traffic by
    overriding :meth:`on_start` and :meth:`on_step` (recording, evaluation-only observers)."""

    def __init__(self, robot: Robot):
        self._robot = robot
        self.spec, self.dt, self.gravity = robot.spec, robot.dt, robot.gravity

    @property
    def base_pose(self) -> np.ndarray:
        return self._robot.base_pose

    def start(self, T_world_base, q0) -> JointReading:
        r = self._robot.start(T_world_base, q0)
        self.on_start(T_world_base, q0, r)
        return r

    def step(self, command: JointCommand) -> JointReading:
        r = self._robot.step(command)
        self.on_step(command, r)
        return r

    def on_start(self, T_world_base, q0, reading: JointReading) -> None:
        """Called after each motion's start with its base pose (4, 4), rest angles (n,) and reading."""

    def on_step(self, command: JointCommand, reading: JointReading) -> None:
        """Called after each step with the command sent and the reading returned."""


class RecordingRobot(ForwardingRobot):
    """Wraps a robot and records every motion start, command and reading (:meth:`log`)."""

    def __init__(self, robot: Robot):
        super().__init__(robot)
        self._base, self._start_q, self._start_index = [], [], []
        self._rows: list = []

    def on_start(self, T_world_base, q0, reading: JointReading) -> None:
        self._base.append(np.asarray(T_world_base, dtype=np.float64).copy())
        self._start_q.append(np.asarray(q0, dtype=np.float64).copy())
        self._start_index.append(len(self._rows))
        self._rows.append((make_command(self.spec, q0), reading))

    def on_step(self, command: JointCommand, reading: JointReading) -> None:
        self._rows.append((command, reading))

    def log(self) -> RobotLog:
        """Everything recorded so far."""
        n = self.spec.n_links
        col = lambda f: np.array([f(c, r) for c, r in self._rows], dtype=np.float64).reshape(len(self._rows), -1)
        return RobotLog(
            spec=self.spec, dt=float(self.dt), gravity=np.asarray(self.gravity, dtype=np.float64),
            base_T=np.array(self._base).reshape(-1, 4, 4), start_q=np.array(self._start_q).reshape(-1, n),
            start_index=np.array(self._start_index, dtype=np.int64),
            t_s=col(lambda c, r: r.t_s)[:, 0], q=col(lambda c, r: r.q), dq=col(lambda c, r: r.dq),
            tau=col(lambda c, r: r.tau), q_ref=col(lambda c, r: c.q_ref), dq_ref=col(lambda c, r: c.dq_ref),
            torque_limit=col(lambda c, r: c.torque_limit), tau_ff=col(lambda c, r: c.tau_ff),
        )


class LogMismatchError(ValueError):
    """A controller replayed against a :class:`LogRobot` did something other than what the log
    recorded (a different base pose, start angles or command)."""


class LogRobot(Robot):
    """Plays a :class:`RobotLog` back: each ``start``/``step`` returns the recorded reading, after
    checking that the controller asks for what was recorded (``atol`` on every number), so a
    controller replayed through it takes the same decisions as when the log was recorded.

    ``check_tau_ff=False`` skips the feed-forward check (it is computed from readings, so an
    estimator replaying a real robot's log with a different model may differ there).
    """

    def __init__(self, log: RobotLog, atol: float = 1e-12, check_tau_ff: bool = True):
        log.check()
        self._log = log
        self.spec, self.dt, self.gravity = log.spec, log.dt, np.asarray(log.gravity, dtype=np.float64)
        self._atol = atol
        self._check_ff = check_tau_ff
        self._motion = -1
        self._i = -1
        self._end = 0

    @property
    def base_pose(self) -> np.ndarray:
        return self._log.base_T[self._motion].copy()

    @property
    def finished(self) -> bool:
        """Every motion and step of the log has been played."""
        return self._motion == self._log.n_motions - 1 and self._i == self._end - 1


    def start(self, T_world_base, q0) -> JointReading:
        L = self._log
        m = self._motion + 1
        if m >= L.n_motions:
            raise LogMismatchError(f"the log holds {L.n_motions} motions; a motion {m + 1} was started")
        for what, got, want in (("base pose", T_world_base, L.base_T[m]), ("start angles", q0, L.start_q[m])):
            if not np.allclose(np.asarray(got, dtype=np.float64), want, rtol=0.0, atol=self._atol):
                raise LogMismatchError(f"motion {m}: the {what} differ from the log's")
        self._motion = m
        self._i = int(L.start_index[m])
        self._end = int(L.start_index[m + 1]) if m + 1 < L.n_motions else L.n_steps
        return self._log.reading(self._i)

    def step(self, command: JointCommand) -> JointReading:
        L = self._log
        i = self._i + 1
        if self._motion < 0 or i >= self._end:
            raise LogMismatchError(f"motion {self._motion}: the log has no step {i - int(L.start_index[max(self._motion, 0)])}")
        checks = [("q_ref", command.q_ref), ("dq_ref", command.dq_ref), ("torque_limit", command.torque_limit)]
        if self._check_ff:
            checks.append(("tau_ff", command.tau_ff))
        for name, got in checks:
            if not np.allclose(got, getattr(L, name)[i], rtol=0.0, atol=self._atol):
                raise LogMismatchError(f"motion {self._motion}, log row {i}: the command's {name} differs from the log's")
        self._i = i
        return self._log.reading(self._i)


class LogWorkcell(Workcell):
    """A workcell of recorded wraps: the robot of wrap ``i`` plays ``logs[i]`` back
    (:class:`LogRobot`, which checks that every command is the recorded one).  A strategy run on
    it repeats a recorded exploration (a simulated one's :attr:`Exploration.logs
    <explore3d.strategy.explore.Exploration.logs>`, or a real arm's logs, one :class:`RobotLog`
    per wrap) without the world that made it.  Picklable.

    Args:
        logs: one :class:`RobotLog` per wrap, in wrap order.
        atol, check_tau_ff: as :class:`LogRobot`'s.
    """

    def __init__(self, logs, atol: float = 1e-12, check_tau_ff: bool = True):
        self.logs = tuple(logs)
        if not self.logs:
            raise ValueError("LogWorkcell needs at least one RobotLog (one per wrap); got none")
        specs = {log.spec for log in self.logs}
        if len(specs) != 1:
            raise ValueError(f"LogWorkcell's logs must all be of one arm; got {len(specs)} different ArmSpecs")
        self.spec = self.logs[0].spec
        self.steps = 0
        self._atol, self._check_ff = atol, check_tau_ff

    def robot(self, sensors: SensorConfig = SensorConfig(), wrap: int | None = None) -> Robot:
        if wrap is None or not 0 <= wrap < len(self.logs):
            raise ValueError(f"LogWorkcell holds the logs of wraps 0..{len(self.logs) - 1}; asked for wrap {wrap!r}")
        return _CountingRobot(LogRobot(self.logs[wrap], self._atol, self._check_ff), self)

    def __call__(self) -> "LogWorkcell":
        """The factory protocol: each call opens a fresh cell over the same logs."""
        return LogWorkcell(self.logs, self._atol, self._check_ff)


class _CountingRobot(ForwardingRobot):
    """Counts the control steps a :class:`LogWorkcell`'s robot plays into the cell's ``steps``
    (one physics step per control step, as the simulated arm's)."""

    def __init__(self, robot: Robot, cell: LogWorkcell):
        super().__init__(robot)
        self._cell = cell

    def on_step(self, command, reading) -> None:
        self._cell.steps += 1
