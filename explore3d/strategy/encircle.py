"""The encirclement strategy of the paper (section III), driven by joint error alone.

One *attempt*: the arm starts straight; the most proximal joint sweeps its reference towards the
curl (+ angles) carrying the straight distal links; when any joint's position error leaves its
calibrated free-motion band the swept joint is taken to be in contact: it is held there (optionally
with a small inward bias, the paper's proposal against relaxation) and the next joint sweeps; this
goes on until every joint has made contact or reached its limit.  A curling chain can also touch
itself (the simulation collides the arm with itself, :attr:`explore3d.core.settings.SimConfig.self_collision`):
a detection at which the arm's own model puts a link the swept joint carries against the base block
or a link before it is a self-contact (:mod:`explore3d.arm.selfcontact`), not the object's: no contact
is recorded and the attempt ends there (or, with ``ControlConfig.self_contact_action="retreat"``,
the joint backs off and the next joint sweeps).  One *wrap*: several attempts
from one base pose, the base joint stopping a step short of its previous stop angle each time.

The code here sees the arm only through the :class:`~explore3d.robot.interface.Robot` interface: joint
readings, its own commands and model, the known base pose.  No contact queries, ray tests or
object poses (a test runs a whole exploration with those PyBullet functions removed).
"""
from __future__ import annotations

import collections
import dataclasses
import enum
import math
from dataclasses import dataclass

import numpy as np

from explore3d.arm.kinematics import gravity_torques, link_frames_planar
from explore3d.arm.selfcontact import SELF_CONTACT_TOLERANCE_M, self_contact_pairs, self_distances
from explore3d.arm.spec import ArmSpec
from explore3d.arm.workspace import floor_stop
from explore3d.core.validate import check_field
from explore3d.feeling.detect import DETECTORS, ContactBand, ExternalTorque, SweepDetector
from explore3d.feeling.localise import external_torques, localise
from explore3d.robot.interface import JointCommand, JointReading, Robot

#: A detection is a self-contact when any of the sweep's last this many readings put a carried body
#: against one the joint does not carry (the detector's two-step mean, the sensing delay and a
#: collision's rebound fit inside).  Measured on a planar wrap of the cube: the tip link slid along
#: the base block, touching it for several steps (model distance -0.2 to +0.1 mm), then flipped
#: 0.4 rad away within one step; the detection's own reading put it 4 mm from the block.
SELF_CONTACT_WINDOW_STEPS = 8


class StopReason(enum.Enum):
    """Why a joint's sweep ended."""

    CONTACT = "contact"  #: a joint error left its band
    SELF = "self_contact"  #: a joint error left its band while the arm's model put two of its own bodies in touch
    LIMIT = "limit"  #: the reference reached the joint limit without contact
    STOP_ANGLE = "stop_angle"  #: the base joint reached this attempt's stop angle (attempts after the first)
    TIMEOUT = "timeout"  #: the sweep ran out of steps
    WRAPPED = "wrapped"  #: not swept: the chain before it had already curled a full turn (``max_curl``)
    ENDED = "ended"  #: not swept: the attempt ended at a self-contact (``ControlConfig.self_contact_action``)
    #: only joints behind a link already on the object left their torque bands: the sweep was pressing the held links
    #: harder onto the object, no new touch (``ControlConfig.held_load_action`` "stop")
    LOADED = "loaded"


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
        band_factor: the contact band of each joint is ``band_factor`` (dimensionless, >= 1)
            times the largest signal measured without contact by
            :func:`explore3d.world.band.calibrate_band` (free motion and contact-free sweeps on the
            known calibration ball).
        hold_bias: held joints' reference is set this far beyond the angle at contact, rad, in
            the curl direction (the paper's proposed small inward push; 0 holds in place).
        limit_margin: sweeps stop this far short of the joint's upper limit, rad.
        sweep_torque_factor: the swept joint's motor torque limit is this times what free motion
            needs (its gravity bound, :meth:`~explore3d.arm.spec.ArmSpec.gravity_torques`, plus the
            distal chain's inertia bound times the ramp's acceleration ``speed / ramp_time``) ...
        sweep_torque_margin: ... plus this, N m.  Held and distal joints keep the full motor
            torque, so a contact anywhere on the distal chain stalls the swept joint instead of
            knocking a held joint away.
        watch_held: also watch the held (proximal) joints' errors; off, only the swept joint's
            lag and the not-yet-swept (distal) joints' errors signal contact.
        gravity_compensation: the motors cancel the links' weights with a feed-forward torque
            computed from the arm's own model, the sensed joint angles, the known base pose and
            gravity; the swept joint's torque limit then leaves gravity out.
        rereference_held: after each detection the held joints' references are reset to their
            measured angles (no held joint stays saturated against the object).  On by default:
            measured on the calibration ball, held links pressing against the object at full
            torque chattered (contact forces jumping between 0 and 15-24 N from step to step) and
            shook the chain; with re-referencing the contact-free signals, and so the measured
            bands, shrank 3-30x (BENCHMARKS.md).
        max_curl: a joint is not swept once the joints before it have curled this much in
            total, rad (2 pi: the chain has gone once around the object; beyond, it would lie
            over itself).
        settle_steps: steps the arm is held still after being reset straight and after each
            sweep (lets the impact of a contact die out before the next joint moves).
        press_while_settling: during a contact's settle (below) the swept joint keeps its sweep
            reference (ahead of where it stalled) and its sweep torque limit, so it goes on pressing
            the touching link gently against the object and the settled reading carries the
            contact's force; afterwards it is held where it stands with the full torque.  If the
            pressing arm does not come to rest within ``contact_settle_steps`` it is held where it
            stands and settles again (the reading is then that second settle's).  Off: it is held
            where it stalled from the detection on, and the contact may relax to no force before
            the reading (a contact without force cannot be localised).
        contact_settle_steps: after a detected contact the arm is held until it is still (below),
            at most this many steps (>= ``settle_steps``); the reading then is the attempt's
            *moment* for that contact (:attr:`Attempt.moments`): a quasi-static reading the
            contacts are localised from (:mod:`explore3d.feeling.localise`).  Equal to ``settle_steps``:
            a fixed hold, no stillness test.
        still_speed: the arm is *still* when every joint's reported speed has stayed at or below
            this, rad/s, for ``still_steps`` consecutive readings (the default is just above one
            velocity unit of the default sensing, 0.024 rad/s, so a still joint reads 0 or one unit).
        still_steps: consecutive still readings that end a contact's settle.  Over that window
            the mean acceleration of every joint is bounded by about ``2 still_speed /
            (still_steps dt)``, which bounds the chain's unmodelled inertial torques.
        max_sweep_steps: safety cap on the steps of one joint's sweep.
        self_contact_tolerance: a detection is the arm touching itself, not the object, when by
            the arm's own model at the sensed angles of any of the sweep's last
            :data:`SELF_CONTACT_WINDOW_STEPS` readings a body the swept joint k carries (link k and
            beyond) is within this distance, m, of one it does not (the base block, links before
            k; non-adjacent pairs only, :func:`explore3d.arm.selfcontact.self_contact_pairs`): the
            pairs the sweep moved together (the carried chain is straight, the held one did not
            move).  The sweep then ends (:attr:`StopReason.SELF`): no contact and no settled
            reading are recorded, and ``self_contact_action`` says what follows.
            Default 1 mm: measured on 12 wraps of the 80 mm cube (default 3D setting), every
            detection at which PyBullet reported an arm-arm contact (43) had the model put that
            pair within 0.06 mm (0.37 mm with an earlier version of this rule; the model's sharp
            boxes are never farther apart than PyBullet's rounded ones; the sensed angles are one
            step late and quantised), and every one became a self-contact; 15 more self-contacts
            had the touch in the window only, and at none of the 58 did a carried link touch the
            cube.
        self_contact_action: after a self-contact, ``"end"`` (default): the joints are held where
            they stand and the attempt ends (the joints after k are not swept,
            :attr:`StopReason.ENDED`); ``"retreat"``: the joints up to k are held, the joint
            nearest the touch that can part the bodies backs off until the model parts them by
            twice ``self_contact_tolerance`` (:func:`retreat`), the arm settles and the next joint
            sweeps (backing off, not pressing on: measured in free space, a chain held pressing
            against itself chattered and the next sweeps detected at once, 5 false contacts in one
            attempt of the default arm).  Measured (default arm, 80 mm cube; BENCHMARKS.md,
            "Self-collision"): the back-off's later sweeps, the distal chain bent out of the
            straight shape the bands were measured with, gave 9 false detections in 79 (4 wraps,
            3D; 4 in 74 ending) and the default 3D run's volume error 2.75% (2.25% ending).
        rereference_distal: after each detection the joints beyond the swept one are also held
            at their measured angles (off: they stay referenced straight with the full torque, and
            a distal link bent by the touch is pushed back into the object; measured on the cube
            resting on a table, that settle shoved it 7 mm).
        press_force_n: contact at a known force (with ``press_while_settling``): once the press
            has come to rest the contact's force and lever about the swept joint are estimated
            from the reading (:func:`explore3d.feeling.localise.localise`, the robot's own model),
            and the swept joint's torque limit is moved, over ``press_ramp_steps``, to what
            presses the carried links with this force, N (at most
            :data:`PRESS_ITERATIONS` corrections, each settled); None: the sweep's own torque
            limit presses (the force then depends on where the touch is: tens of mN at the
            gentle sweeps' 2 mN m margin).  The force a resting object's friction can hold is
            the budget (:func:`force_budget_n`).
        press_ramp_steps: steps over which the torque limit moves to a new press (no step in
            the contact force: a step change kicks a light object).
        average_steps: after the moment's settle, hold this many more steps with the same
            references and limits and report the mean of their readings (angles, velocities,
            torques) as the moment (:attr:`Moment.readings`; the torque noise of the mean falls
            as ``1 / sqrt(n)``); 0: the settle's last reading.
        detector: ``"stall"`` (default): a contact is a position error leaving its band (the
            paper's rule, :class:`~explore3d.feeling.detect.SweepDetector`); ``"torque"``: also
            every joint's external torque leaving its band (the residual of the arm's model
            against the reported motor torques, :class:`~explore3d.feeling.detect.ExternalTorque`;
            issue 40): a touch anywhere on the chain, even beside the swept joint's axis, shows
            on the joints proximal to it over their long levers.  Its band needs a calibration
            with the same detector (the band's ``torque``).
        held_load_action: what a torque-detector stop does when only the joints behind a link
            already lying on the object left their bands
            (:meth:`~explore3d.feeling.detect.SweepDetector.only_loaded`: the sweep presses the
            held links harder onto the object, the links it carries touch nothing): ``"stop"``
            (default) ends the sweep where it stands, records no contact and goes on with the next
            joint (:attr:`StopReason.LOADED`); ``"contact"`` records it as a contact of the swept
            link, as every detection was before.  The stall detector has no such stops.
    """

    speed: float = 3.0
    tip_speed: float | None = 0.3
    ramp_time: float = 0.05
    band_factor: float = 1.5
    hold_bias: float = 0.0
    limit_margin: float = 0.02
    sweep_torque_factor: float = 1.5
    sweep_torque_margin: float = 0.05
    watch_held: bool = False
    gravity_compensation: bool = True
    rereference_held: bool = True
    max_curl: float = 2 * math.pi
    settle_steps: int = 3
    press_while_settling: bool = True
    contact_settle_steps: int = 40
    still_speed: float = 0.03
    still_steps: int = 8
    max_sweep_steps: int = 2000
    self_contact_tolerance: float = SELF_CONTACT_TOLERANCE_M
    self_contact_action: str = "end"
    rereference_distal: bool = False
    press_force_n: float | None = None
    press_ramp_steps: int = 24
    average_steps: int = 0
    detector: str = "stall"
    held_load_action: str = "stop"

    @classmethod
    def gentle(cls) -> "ControlConfig":
        """Sweeps for an object that can move (:class:`explore3d.core.settings.SceneConfig` ``resting``):
        the tip at most 0.06 m/s (5x slower: an impact's momentum 5x smaller, the slide it causes
        25x shorter), the speed ramped over 0.2 s, the swept joint's torque 1.5 x what that motion
        needs plus 2 mN m (force at a contact ``d`` metres from the joint: that over ``d``), and
        after a detection every joint beyond the swept one held where it is
        (``rereference_distal``)."""
        return cls(tip_speed=0.06, ramp_time=0.2, sweep_torque_margin=0.002, max_sweep_steps=8000,
                   rereference_distal=True)

    @classmethod
    def within_budget(cls, spec: ArmSpec, force_n: float, lever_m: float | None = None,
                      base: ControlConfig | None = None) -> ControlConfig:
        """``base`` (default :meth:`gentle`) with its speed ramp lengthened until every swept joint's
        torque limit (:func:`sweep_torque_limits`) is at most ``force_n`` N times ``lever_m`` m
        (default two of ``spec``'s link lengths): a touch that far or farther from the swept joint
        then presses with at most ``force_n`` (the stalled joint's torque over the lever), nearer
        touches are on links the next joints sweep with smaller limits.  The ramp sets what a
        sweep needs to accelerate its distal chain, so the limits fall as it lengthens; the
        margin (``sweep_torque_margin``) is left as it is.

        Raises:
            ValueError: the budget is below the margin, which no ramp can meet.
        """
        base = cls.gentle() if base is None else base
        lever = 2.0 * spec.link_length if lever_m is None else float(lever_m)
        cap = float(force_n) * lever
        if not (math.isfinite(cap) and cap > base.sweep_torque_margin):
            raise ValueError(f"ControlConfig.within_budget: force_n x lever_m = {cap:.3g} N m must exceed the sweep's "
                             f"torque margin {base.sweep_torque_margin:.3g} N m; raise the budget or lower the margin")
        room = (cap - base.sweep_torque_margin) / base.sweep_torque_factor  # for the acceleration (and gravity)
        if not base.gravity_compensation:
            room = room - np.array(spec.gravity_torques())
        if np.any(room <= 0):
            raise ValueError(f"ControlConfig.within_budget: {force_n:g} N at {lever:g} m does not hold the arm's own weight "
                             "without gravity compensation; raise the budget or compensate gravity")
        accel_per_ramp = np.array(spec.inertia_bounds()) * sweep_speeds(spec, base)  # N m s: need x ramp time
        ramp = max(base.ramp_time, float(np.max(accel_per_ramp / room)))
        return dataclasses.replace(base, ramp_time=ramp)

    def __post_init__(self):
        check_field(self, "speed", 0, "rad/s", strict=True)
        if self.tip_speed is not None:
            check_field(self, "tip_speed", 0, "m/s (or None)", strict=True)
        check_field(self, "band_factor", 1)
        check_field(self, "sweep_torque_factor", 0, strict=True)
        check_field(self, "max_curl", 0, "rad", strict=True)
        for name, unit in (("ramp_time", "s"), ("hold_bias", "rad"), ("limit_margin", "rad"),
                           ("sweep_torque_margin", "N m")):
            check_field(self, name, 0, unit)
        check_field(self, "settle_steps", 0, integer=True)
        check_field(self, "contact_settle_steps", self.settle_steps, integer=True)
        check_field(self, "still_speed", 0, "rad/s")
        check_field(self, "still_steps", 1, integer=True)
        check_field(self, "max_sweep_steps", 1, integer=True)
        check_field(self, "self_contact_tolerance", 0, "m")
        if self.press_force_n is not None:
            check_field(self, "press_force_n", 0, "N (or None)", strict=True)
            if not self.press_while_settling:
                raise ValueError("ControlConfig.press_force_n needs press_while_settling=True (the press is the "
                                 "swept joint's settle against the object): set it or drop press_force_n")
        check_field(self, "press_ramp_steps", 0, integer=True)
        check_field(self, "average_steps", 0, integer=True)
        if self.detector not in DETECTORS:
            raise ValueError(f"ControlConfig.detector must be one of {DETECTORS}; got {self.detector!r}")
        if self.held_load_action not in ("stop", "contact"):
            raise ValueError(f"ControlConfig.held_load_action must be 'stop' or 'contact'; got {self.held_load_action!r}")
        if self.self_contact_action not in ("retreat", "end"):
            raise ValueError(f"ControlConfig.self_contact_action must be 'retreat' or 'end'; got {self.self_contact_action!r}")
        for name in ("watch_held", "gravity_compensation", "rereference_held", "press_while_settling",
                     "rereference_distal"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"ControlConfig.{name} must be True or False; got {getattr(self, name)!r}")


@dataclass(frozen=True)
class CurlBack:
    """The curl-back encirclement the paper proposes (Future Work): after the first detected contact
    the links beyond the swept joint, except ``straight_links`` of them, curl back away from the
    object; after every further sweep the curl rolls on by one link, so the chain unravels around
    the object as contacts are found.

    The joint swept next then carries ``straight_links`` straight links and a curl that turns away
    from the object, not a straight rod as long as the rest of the chain: the straight sweep's rod
    meets the far rim of a pocket before its near links reach into it (a string around the cross
    section), the short finger reaches in.  The curl is a hairpin of joints bent outward (negative
    angles) by equal amounts totalling ``turn``; the links beyond it are straight, running back
    beside the chain, away from the object.  Between sweeps the arm moves to the next curl at the
    controller's ``speed`` and ``tip_speed`` (:meth:`Controller.move`) with every motor's full
    torque (the motion only turns links away from
    the object, or straightens the finger's next link as the straight sweep's chain starts).

    Attributes:
        straight_links: straight links beyond the swept joint (>= 1; the paper's "except for a few").
        turn: the curl's total outward turn, rad (pi: the links beyond run back beside the chain).
        bend: the largest outward bend of one curled joint, rad; the curl's joints share ``turn``
            equally in as few joints as this allows.  Must fit the arm's lower joint limit less the
            controller's ``limit_margin`` (checked when an attempt starts).
    """

    straight_links: int = 2
    turn: float = math.pi
    bend: float = 0.45

    def __post_init__(self):
        check_field(self, "straight_links", 1, integer=True)
        check_field(self, "turn", 0, "rad", strict=True)
        check_field(self, "bend", 0, "rad", strict=True)

    def offsets(self, spec: ArmSpec, cfg: "ControlConfig", j: int) -> np.ndarray:
        """(n,) references, rad, of the joints beyond joint ``j`` while ``j`` is swept (entries up
        to ``j`` are 0 and not used): ``straight_links`` zeros, then the curl, then zeros."""
        room = -spec.joint_lower - cfg.limit_margin
        if self.bend > room + 1e-12:
            raise ValueError(f"CurlBack.bend must be at most the arm's lower joint limit less the limit margin, "
                             f"{room:.3f} rad; got {self.bend!r} (pass a smaller bend)")
        m = math.ceil(self.turn / self.bend - 1e-9)
        out = np.zeros(spec.n_links)
        first = j + 1 + self.straight_links
        out[first:first + m] = -self.turn / m
        return out


@dataclass(frozen=True)
class Attempt:
    """The result of one attempt.

    Attributes:
        T_world_base: (4, 4) the base pose, world frame.
        q: (n,) measured joint angles at final contact, rad.
        q_ref: (n,) references at the end, rad.
        contact: (n,) bool, joint j's sweep ended by a detected contact.
        reasons: StopReason of each joint's sweep.
        detect_step: (n,) int, the step of the attempt after joint j's sweep and its settle.
        steps: physics steps taken.
        contact_step: (n,) int, the step at which joint j's contact was detected (-1: none).
        moments: one :class:`Moment` per detected contact, in order: the settled reading the
            contacts are localised from.
        trajectory: (t, n) measured joint angles at every step when recorded, else None.
        trajectory_ref: (t, n) references at every step when recorded, else None.
        poke: a tip poke (:func:`explore3d.strategy.poke.run_poke`): the chain bent into a hook,
            so a force on the tip's distal face is seen by the joints (its contacts there count,
            :func:`explore3d.feeling.contacts.localise_attempts`).
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
    contact_step: np.ndarray | None = None
    trajectory_joint: np.ndarray | None = None
    moments: tuple = ()
    poke: bool = False


@dataclass(frozen=True)
class Moment:
    """A quasi-static reading after a detected contact: what the robot knows there.

    Attributes:
        joint: the joint whose sweep detected the contact.
        step: the step of the attempt at which it was read (1-based, as ``detect_step``).
        still: the arm was still by :class:`ControlConfig`'s test (False: the settle ran out).
        reading: the :class:`~explore3d.robot.interface.JointReading` at the end of the settle (angles,
            velocities, motor torques; see :meth:`Controller.settle`), or the mean of ``readings``
            readings held after it (:attr:`ControlConfig.average_steps`).
        readings: how many readings ``reading`` is the mean of (1: a single reading).
    """

    joint: int
    step: int
    still: bool
    reading: JointReading
    readings: int = 1


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


class Controller:
    """Sends commands through the robot interface and adds the model-based gravity feed-forward.

    Args:
        robot: the arm (the :class:`~explore3d.robot.interface.Robot` interface only).
        cfg: the controller settings.
        T_world_base: (4, 4) the known base pose of this motion.
        record: keep the readings and references of every sweep step.
    """

    def __init__(self, robot: Robot, cfg: ControlConfig, T_world_base, record: bool = False):
        self.robot, self.cfg = robot, cfg
        self.spec: ArmSpec = robot.spec
        self.T = np.asarray(T_world_base, dtype=np.float64)
        g = np.asarray(robot.gravity, dtype=np.float64)
        # Gravity along the joint axes (the arm's plane horizontal) loads no joint: nothing to cancel.
        z = self.T[:3, 2]
        self.compensate = cfg.gravity_compensation and float(np.linalg.norm(g - (g @ z) * z)) > 1e-9
        self.full = np.array(self.spec.joint_torques())
        self.zero = np.zeros(self.spec.n_links)
        self.reading: JointReading | None = None
        self.sweep_q: collections.deque = collections.deque(maxlen=SELF_CONTACT_WINDOW_STEPS)  # the sweep's last angles
        self.steps = 0
        self._ff = None  # (angles, feed-forward) of the last step
        self.traj, self.traj_ref, self.traj_joint = ([], [], []) if record else (None, None, None)

    def start(self, q0=None) -> np.ndarray:
        """Begin the motion at rest at ``q0`` (n,) rad (None: the arm straight); returns the first
        reading's angles."""
        self.reading = self.robot.start(self.T, self.zero if q0 is None else np.asarray(q0, dtype=np.float64))
        return self.reading.q

    def send(self, q_ref, dq_ref=None, limits=None) -> np.ndarray:
        """One control step: references (n,) rad, velocity feed-forward (n,) rad/s (default 0),
        torque limits (n,) N m (default the arm's); returns the reading's angles (n,), rad."""
        ff = self._feed_forward(self.reading.q) if self.compensate else self.zero
        cmd = JointCommand(q_ref=q_ref.copy(), dq_ref=self.zero if dq_ref is None else dq_ref.copy(),
                           torque_limit=self.full if limits is None else limits, tau_ff=ff)
        self.reading = self.robot.step(cmd)
        self.steps += 1
        return self.reading.q

    def _feed_forward(self, q: np.ndarray) -> np.ndarray:
        """(n,) the gravity feed-forward, N m, at the reading's angles ``q`` (n,), rad: computed again
        only when the reading changes (quantised encoders repeat while a joint is still)."""
        if self._ff is None or not np.array_equal(q, self._ff[0]):
            ff = -gravity_torques(self.spec, q, self.T, self.robot.gravity)
            ff.flags.writeable = False
            self._ff = (q.copy(), ff)
        return self._ff[1]

    def hold(self, q_ref) -> np.ndarray:
        """Hold ``q_ref`` for ``settle_steps`` steps; returns the last reading's angles."""
        q = self.reading.q
        for _ in range(self.cfg.settle_steps):
            q = self.send(q_ref)
        return q

    def move(self, q_from, q_to) -> np.ndarray:
        """Move the references from ``q_from`` to ``q_to`` (n,), rad, on a cosine profile with
        every motor's full torque, then settle (:meth:`settle`); returns the last reading's angles.

        The profile's peak speed is the controller's ``speed`` for the fastest joint and, as for
        the sweeps, ``tip_speed`` for the fastest point of the chain (its path, in the arm's own
        model, along the interpolation).  Measured: with the joint speed alone (3 rad/s) the
        curl-back's first hairpin swung 19 links through 180 degrees in 0.15 s; on the capsule the
        chain, pressed against the object, blew up (joints jumping 0.4 rad per step, past their
        limits) and a link passed through the object, whose swept space then carved the estimate
        (11.7% against 2.0% volume error).
        """
        q_from, q_to = np.asarray(q_from, float), np.asarray(q_to, float)
        span = float(np.max(np.abs(q_to - q_from), initial=0.0))
        duration = span / self.cfg.speed
        if self.cfg.tip_speed is not None and span > 0:
            s = np.linspace(0.0, 1.0, 17)[:, None]
            origins, headings = link_frames_planar(self.spec, q_from + s * (q_to - q_from))
            tip = origins[:, -1] + self.spec.link_length * np.stack([np.cos(headings[:, -1]),
                                                                     np.sin(headings[:, -1])], axis=-1)
            pts = np.concatenate([origins, tip[:, None]], axis=1)  # (17, n + 1, 2)
            path = np.linalg.norm(np.diff(pts, axis=0), axis=-1).sum(axis=0).max()
            duration = max(duration, float(path) / self.cfg.tip_speed)
        steps = math.ceil(math.pi / 2 * duration / self.robot.dt)
        for i in range(1, steps + 1):
            f = 0.5 - 0.5 * math.cos(math.pi * i / steps)
            self.send(q_from + f * (q_to - q_from))
        self.settle(q_to)
        return self.reading.q

    def settle(self, q_ref, limits=None) -> tuple[bool, JointReading]:
        """Hold ``q_ref`` at least ``settle_steps`` and at most ``contact_settle_steps`` steps,
        until the arm is still (see :class:`ControlConfig`); ``limits`` (n,) N m: the motors'
        torque limits meanwhile (default the arm's).

        Returns:
            whether it was still, and the last reading (angles, velocities, motor torques).
            Measured: the mean or the median of the still window's readings located worse than
            the last one (default 3D box before the pressing settle: 22% / 25% volume error
            against 12%; the position loops trade corrective impulses every few steps, which a
            window mixes in).
        """
        cfg = self.cfg
        run = 0
        for i in range(cfg.contact_settle_steps):
            self.send(q_ref, None, limits)
            run = run + 1 if float(np.max(np.abs(self.reading.dq))) <= cfg.still_speed else 0
            if i + 1 >= cfg.settle_steps and (run >= cfg.still_steps or cfg.contact_settle_steps == cfg.settle_steps):
                break
        return run >= cfg.still_steps, self.reading

    def average(self, q_ref, limits, n: int) -> JointReading:
        """Hold ``q_ref`` with ``limits`` (None: the arm's) for ``n`` steps; the mean of their
        readings (angles, velocities, torques; the last one's time)."""
        rs = []
        for _ in range(n):
            self.send(q_ref, None, limits)
            rs.append(self.reading)
        return JointReading(t_s=rs[-1].t_s, q=np.mean([r.q for r in rs], axis=0),
                            dq=np.mean([r.dq for r in rs], axis=0), tau=np.mean([r.tau for r in rs], axis=0))


#: At most this many corrections of the press's torque limit towards :attr:`ControlConfig.press_force_n`.
PRESS_ITERATIONS = 3

#: A press within this fraction of its target force is not corrected further.
PRESS_TOLERANCE = 0.15


def force_budget_n(least_mass_kg: float, friction: float, margin: float = 0.5, g: float = 9.81) -> float:
    """The largest contact force, N, a wrap may press a resting object with: ``margin`` (0-1] times
    the static friction ``friction * least_mass_kg * g`` that holds the lightest object expected
    (a single horizontal push; the object's own weight is its only load on the table)."""
    for name, v in (("least_mass_kg", least_mass_kg), ("friction", friction), ("margin", margin)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ValueError(f"force_budget_n: {name} must be a finite number > 0; got {v!r}")
    if margin > 1:
        raise ValueError(f"force_budget_n: margin must be at most 1 (a fraction of the static friction); got {margin!r}")
    return float(margin * friction * least_mass_kg * g)


def carried_force(spec: ArmSpec, reading: JointReading, k: int, T_world_base, gravity) -> tuple[float, float | None]:
    """The contact force on the links joint ``k`` carries (k and beyond), N, and its mean lever
    about joint ``k`` (the external torque there over that force), m, from one reading through the
    arm's own model (:func:`explore3d.feeling.localise.localise`); (0, None) when the torques show
    no contact."""
    tau_ext = external_torques(spec, reading.q, reading.tau, T_world_base, gravity)
    loc = localise(spec, reading.q, tau_ext, T_world_base)
    f = float(sum(c.force_n for c in loc.contacts if c.link >= k))
    if f <= 0.0:
        return 0.0, None
    return f, abs(float(tau_ext[k])) / f


def press_to_force(ctl: Controller, k: int, q_ref: np.ndarray, limits: np.ndarray, force_n: float
                   ) -> tuple[bool, JointReading]:
    """Move the swept joint ``k``'s torque limit (in place in ``limits`` (n,), N m) so the carried
    links press with ``force_n`` N (:attr:`ControlConfig.press_force_n`): estimate the force and
    its lever (:func:`carried_force`), ramp the limit by the difference times the lever over
    ``press_ramp_steps`` steps, settle, repeat (at most :data:`PRESS_ITERATIONS` times, until
    within :data:`PRESS_TOLERANCE`).  With no force seen the lever is taken as half a link (the
    nearest a touch on the carried chain can be: the smallest step).  Returns the last settle's
    stillness and reading."""
    still, reading = True, ctl.reading
    for _ in range(PRESS_ITERATIONS):
        f, lever = carried_force(ctl.spec, reading, k, ctl.T, ctl.robot.gravity)
        if lever is not None and abs(f - force_n) <= PRESS_TOLERANCE * force_n:
            break
        lever = ctl.spec.link_length / 2.0 if lever is None else max(lever, ctl.spec.link_length / 2.0)
        start = float(limits[k])
        target = max(0.0, start + (force_n - f) * lever)
        n_ramp = max(1, ctl.cfg.press_ramp_steps)
        for i in range(1, n_ramp + 1):
            limits[k] = start + (target - start) * i / n_ramp
            ctl.send(q_ref, None, limits)
        still, reading = ctl.settle(q_ref, limits)
        if not still:
            break
    return still, reading


def settle_touch(ctl: Controller, k: int, q_ref: np.ndarray, sweep_torque: float, contact: np.ndarray) -> Moment:
    """After joint ``k``'s sweep detected a touch at the reading ``ctl.reading``: re-reference the
    held joints and the carried chain (:class:`ControlConfig`; ``q_ref`` (n,) rad changes in place,
    ``contact`` (n,) bool marks the joints whose sweeps touched so far), settle pressing with the
    sweep's torque limit ``sweep_torque`` N m (then with the chosen force) or holding where it
    stands, read the quasi-static moment, and hold there with the full torque.  Returns the
    :class:`Moment` the touch is localised from."""
    cfg = ctl.cfg
    q = ctl.reading.q
    if cfg.rereference_held:
        q_ref[:k] = q[:k] + cfg.hold_bias * contact[:k]
    if cfg.rereference_distal:  # the carried chain, bent by the touch, does not push back
        q_ref[k + 1:] = q[k + 1:]
    still, held = False, None
    if cfg.press_while_settling:  # keep the sweep's reference and torque limit: a gentle push
        held = ctl.full.copy()
        held[k] = sweep_torque
        still, reading = ctl.settle(q_ref, held)
        if still and cfg.press_force_n is not None:  # then press with the chosen force
            still, reading = press_to_force(ctl, k, q_ref, held, cfg.press_force_n)
    if not still:  # hold where it stands (after a press that never came to rest: let go)
        q_ref[k] = ctl.reading.q[k] + cfg.hold_bias
        held = None
        still, reading = ctl.settle(q_ref)
    n_read = 1
    if still and cfg.average_steps:
        reading, n_read = ctl.average(q_ref, held, cfg.average_steps), cfg.average_steps
    moment = Moment(joint=k, step=ctl.steps, still=still, reading=reading, readings=n_read)
    if cfg.press_while_settling:  # then hold where it is with the full torque
        q_ref[k] = ctl.reading.q[k] + cfg.hold_bias
        ctl.hold(q_ref)
    return moment


def sweep_joint(ctl: Controller, k: int, q_ref: np.ndarray, stop: float, band: ContactBand | None,
                speed: float, torque_limit: float, is_base_stop: bool = False, observer=None,
                loaded: int = -1) -> StopReason:
    """Sweep joint ``k``'s reference (in place in ``q_ref`` (n,), rad) towards ``stop`` rad at up to
    ``speed`` rad/s with motor torque limit ``torque_limit`` N m, until the detector fires
    (``band``; None: never) or the stop is reached.  ``observer(k, reading, lag, sig)`` sees every
    step's filtered signals; if it returns True or False that is the step's verdict instead of the
    band's (the band calibration's known-object rule), None keeps the band's.  With
    ``ControlConfig.detector == "torque"`` the observer is called with a fifth argument, the
    filtered external-torque change (n,), N m, and a sixth, ``loaded`` (the most distal joint whose
    sweep detected a contact earlier in the attempt, -1: none; its torque band and those before it
    are ``ContactBand.torque_loaded``, :class:`~explore3d.feeling.detect.SweepDetector`)."""
    cfg, dt = ctl.cfg, ctl.robot.dt
    n = len(q_ref)
    at_stop = StopReason.STOP_ANGLE if is_base_stop else StopReason.LIMIT
    if q_ref[k] >= stop:
        return at_stop
    dq_ref = np.zeros(n)
    limits = ctl.full.copy()
    limits[k] = torque_limit
    ext_model = ExternalTorque(ctl.spec, ctl.T, ctl.robot.gravity) if cfg.detector == "torque" else None
    r0 = ctl.reading
    det = SweepDetector(k, q_ref, r0.q, cfg.watch_held,
                        ext0=None if ext_model is None else ext_model(r0.q, r0.dq, r0.tau), loaded=loaded)
    ddq = np.zeros(n)  # the commanded acceleration of the step the reading shows (one step back)
    w_prev = 0.0
    ctl.sweep_q.clear()
    for i in range(cfg.max_sweep_steps):
        # speed ramps up from rest and down again before the stop angle (no false alarm there)
        w = min(_ramp_speed(speed, cfg.ramp_time, i * dt),
                _ramp_speed(speed, cfg.ramp_time, max(0.0, (stop - q_ref[k]) / speed)))
        w = max(w, speed * 0.05)
        prev = q_ref[k]
        q_ref[k] = min(stop, q_ref[k] + w * dt)
        dq_ref[k] = w if q_ref[k] < stop else 0.0
        q = ctl.send(q_ref, dq_ref, limits)
        ctl.sweep_q.append(q)
        if ctl.traj is not None:
            ctl.traj.append(q)
            ctl.traj_ref.append(q_ref.copy())
            ctl.traj_joint.append(k)
        lag, sig = det.update(prev, q_ref, q)
        ext = None
        if ext_model is not None:
            r = ctl.reading
            ext = det.update_torque(ext_model(r.q, r.dq, r.tau, ddq))
            ddq[k] = (dq_ref[k] - w_prev) / dt
            w_prev = dq_ref[k]
        if observer is None:
            verdict = None
        else:
            verdict = (observer(k, ctl.reading, lag, sig) if ext is None
                       else observer(k, ctl.reading, lag, sig, ext, loaded))
        if verdict is None:
            verdict = band is not None and (SweepDetector.exceeds(band, k, lag, sig) if ext is None
                                            else SweepDetector.exceeds(band, k, lag, sig, ext, loaded))
        if i > 0 and verdict:
            if (observer is None and ctl.cfg.held_load_action == "stop"
                    and SweepDetector.only_loaded(band, k, lag, sig, ext, loaded)):
                return StopReason.LOADED
            return StopReason.CONTACT
        if q_ref[k] >= stop:
            return at_stop
    return StopReason.TIMEOUT


def retreat_joint(spec: ArmSpec, q, k: int, clearance: float, step: float = 0.02) -> int:
    """The joint to back off after a self-contact stopped joint ``k``'s sweep at angles ``q`` (n,),
    rad: the most distal joint whose turning back towards its lower limit parts, by the model,
    every carried body from every body joint ``k`` does not carry by ``clearance`` metres (tried in
    steps of ``step`` rad), from the touching carried link nearest joint ``k`` down to ``k``; ``k``
    if none does.  Backing off next to the touch leaves the links between joint ``k`` and the touch
    where they lie (on the object)."""
    q = np.asarray(q, dtype=np.float64)
    pairs = self_contact_pairs(spec, q, clearance, moving_from=k)
    if not pairs:
        return k
    for r in range(min(b for _, b in pairs), k - 1, -1):
        angles = np.arange(q[r], spec.joint_lower - step, -step)
        Q = np.repeat(q[None, :], len(angles), axis=0)
        Q[:, r] = np.maximum(angles, spec.joint_lower)
        if (self_distances(spec, Q)[:, : k + 1, k + 1:].min(axis=(1, 2)) >= clearance).any():
            return r
    return k


def retreat(ctl: Controller, k: int, q_ref: np.ndarray, speeds: np.ndarray, clearance: float) -> np.ndarray:
    """After a self-contact stopped joint ``k``'s sweep: hold the joints up to ``k`` where they stand
    and move the reference of the joint :func:`retreat_joint` chooses back (in place in ``q_ref``
    (n,), rad) at its sweep speed (``speeds`` (n,), rad/s) until, by the arm's model at the sensed
    angles, every body joint ``k`` carries is ``clearance`` metres from every body it does not (or
    the reference reaches the lower limit); hold there and settle.  Every motor keeps its full
    torque (a step with a reduced limit is a sweep step, to the replay).  Returns the last
    reading's angles (n,), rad."""
    spec, dt = ctl.spec, ctl.robot.dt
    q = ctl.reading.q
    q_ref[: k + 1] = q[: k + 1]
    r = retreat_joint(spec, q, k, clearance)
    for _ in range(ctl.cfg.max_sweep_steps):
        if q_ref[r] <= spec.joint_lower or not self_contact_pairs(spec, ctl.reading.q, clearance, moving_from=k):
            break
        q_ref[r] = max(spec.joint_lower, q_ref[r] - speeds[r] * dt)
        ctl.send(q_ref)
    _, reading = ctl.settle(q_ref)
    return reading.q


def run_attempt(robot: Robot, T_world_base, band: ContactBand | None, cfg: ControlConfig = ControlConfig(),
                base_stop: float | None = None, record: bool = False, observer=None,
                curl: CurlBack | None = None, floor_z: float | None = None) -> Attempt:
    """One attempt from the base pose ``T_world_base`` (4, 4).

    Args:
        robot: the arm, seen through the :class:`~explore3d.robot.interface.Robot` interface only.
        band: the contact band; None disables detection.
        base_stop: the base joint's stop angle, rad (None: sweep until contact or limit).
        record: keep the joint readings and references of every sweep step.
        observer: ``observer(k, reading, lag, sig)`` called at every sweep step (band calibration;
            see :func:`sweep_joint`).
        curl: the curl-back encirclement (:class:`CurlBack`); None: the straight sweep, every
            joint sweeps with the chain beyond it straight.
        floor_z: a table's known height plus a clearance, world z, m: each joint's sweep stops
            before the chain it carries would dip below it (:func:`explore3d.arm.workspace.floor_stop`,
            on the model at the references; the sweep then ends as at its limit).  None: no floor.
    """
    spec: ArmSpec = robot.spec
    n = spec.n_links
    ctl = Controller(robot, cfg, T_world_base, record)
    q_ref = np.zeros(n)
    ctl.start()
    q = ctl.hold(q_ref)
    upper = spec.joint_upper - cfg.limit_margin
    sweep_torques = sweep_torque_limits(spec, cfg)
    speeds = sweep_speeds(spec, cfg)
    contact = np.zeros(n, dtype=bool)
    reasons: list = []
    detect_step = np.zeros(n, dtype=int)
    contact_step = np.full(n, -1, dtype=int)
    moments: list = []
    if curl is not None:
        curl.offsets(spec, cfg, 0)  # the bend fits the arm (raises before moving)
    for k in range(n):
        if k > 0 and q[:k].sum() >= cfg.max_curl:
            reasons.extend([StopReason.WRAPPED] * (n - k))
            detect_step[k:] = ctl.steps
            break
        if curl is not None and contact.any():  # curl back (after the first contact) or roll on
            target = q_ref.copy()
            target[k + 1:] = curl.offsets(spec, cfg, k)[k + 1:]
            if not np.array_equal(target, q_ref):
                q = ctl.move(q_ref, target)
                q_ref[:] = target
        base = k == 0 and base_stop is not None
        stop = min(upper, base_stop) if base else upper
        if floor_z is not None:
            stop = floor_stop(spec, q_ref, k, ctl.T, floor_z, stop)
        loaded = int(np.flatnonzero(contact).max(initial=-1))
        reason = sweep_joint(ctl, k, q_ref, stop, band, speeds[k], sweep_torques[k], base, observer, loaded)
        q = ctl.reading.q
        if reason is StopReason.CONTACT and any(self_contact_pairs(spec, qs, cfg.self_contact_tolerance, moving_from=k)
                                                for qs in ctl.sweep_q):
            reason = StopReason.SELF
        if reason is StopReason.SELF and cfg.self_contact_action == "end":
            q_ref[: k + 1] = q[: k + 1]
            q = ctl.hold(q_ref)
            reasons.append(reason)
            detect_step[k] = ctl.steps
            reasons.extend([StopReason.ENDED] * (n - k - 1))
            detect_step[k + 1:] = ctl.steps
            break
        if reason is StopReason.SELF:
            q = retreat(ctl, k, q_ref, speeds, 2.0 * cfg.self_contact_tolerance)
        elif reason is StopReason.CONTACT:
            contact[k] = True
            contact_step[k] = ctl.steps
            moments.append(settle_touch(ctl, k, q_ref, sweep_torques[k], contact))
            q = ctl.reading.q
        elif reason is StopReason.LOADED:  # stand where the sweep stopped (going on would push the object), the
            q = ctl.reading.q                # held joints where the push left them, as after a touch
            if cfg.rereference_held:
                q_ref[:k] = q[:k] + cfg.hold_bias * contact[:k]
            q_ref[k] = q[k] + cfg.hold_bias
            q = ctl.hold(q_ref)
        else:
            q = ctl.hold(q_ref)
        reasons.append(reason)
        detect_step[k] = ctl.steps
    return Attempt(
        T_world_base=np.asarray(T_world_base, dtype=float).copy(), q=q.copy(), q_ref=q_ref.copy(), contact=contact,
        reasons=tuple(reasons), detect_step=detect_step, steps=ctl.steps,
        trajectory=np.array(ctl.traj) if record else None, trajectory_ref=np.array(ctl.traj_ref) if record else None,
        trajectory_joint=np.array(ctl.traj_joint, dtype=int) if record else None,
        contact_step=contact_step, moments=tuple(moments),
    )


def run_wrap(robot: Robot, T_world_base, band: ContactBand, attempts: int = 4, base_step: float = 0.1,
             cfg: ControlConfig = ControlConfig(), record: bool = False, curl: CurlBack | None = None,
             floor_z: float | None = None) -> list[Attempt]:
    """``attempts`` attempts from one base pose: the first sweeps the base joint until contact;
    each later one stops the base joint ``base_step`` rad short of the previous stop angle.
    ``curl``: the curl-back encirclement (:class:`CurlBack`), None: the straight sweep; ``floor_z``:
    see :func:`run_attempt`."""
    out = []
    stop = None
    for m in range(attempts):
        att = run_attempt(robot, T_world_base, band, cfg, base_stop=stop, record=record, curl=curl, floor_z=floor_z)
        out.append(att)
        prev = att.q[0] if stop is None else stop
        stop = prev - base_step
        if stop <= 0:
            break
    return out
