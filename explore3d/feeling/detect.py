"""The contact detector: when a joint falls behind its reference (the paper's open-loop reference
controller).  The rule lives here once; the controller (:mod:`explore3d.strategy.encircle`), the band
calibration (:mod:`explore3d.world.band`) and the evaluation layer all use it.

While joint k sweeps, two signals are watched, from the joint readings and the controller's own
references only:

* the swept joint's *lag*: its previous reference minus its reading, rad (the motor aims at the
  reference one step ahead, so ``q_ref - q`` alone reads one step's travel high);
* the other joints' *error change*: ``(q_ref - q) - (q_ref - q)`` at the start of the sweep, rad,
  for the distal (not yet swept) joints, and for the held ones with ``watch_held``.

Each is the mean of this and the previous step (a two-step chatter of a loaded joint cancels, a
contact, a persistent error, does not).  A contact is detected when the lag exceeds
``band.swept[k]`` or any watched error change exceeds ``band.other[j]`` in magnitude.

The *torque* detector (``ControlConfig.detector = "torque"``, a band with ``torque`` bands) also
watches every joint's **external torque** (issue 40): a touch anywhere on the chain shows at once
as ``tau_ext = J^T F`` on every joint proximal to it, over long levers even where the swept joint
sees almost none (a touch on its own link beside its axis).  The estimate is the residual between
the arm's own dynamic model and the torques its servos report (:class:`ExternalTorque`, the
quasi-static form of a momentum observer with the model's inertia torques of the commanded
motion), from what a real arm knows only: sensed angles and velocities, reported motor torques,
its commands, its model, the base pose and gravity.  Its change since the sweep began, the mean
of this and the previous step, is compared with ``band.torque[j]`` on *every* joint j (held,
swept and carried alike): the first joint whose residual leaves its band stops the sweep.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from explore3d.arm.kinematics import gravity_torques
from explore3d.arm.spec import ArmSpec

__all__ = ["ContactBand", "SweepDetector", "ExternalTorque", "inverse_dynamics_planar", "DETECTORS"]

#: The detectors (``ControlConfig.detector``): ``"stall"``, position errors only (the paper's
#: open-loop reference rule); ``"torque"``, those and every joint's external torque.
DETECTORS = ("stall", "torque")


def inverse_dynamics_planar(spec: ArmSpec, q, dq, ddq) -> np.ndarray:
    """(n,) joint torques, N m, that move the planar chain with angles ``q`` (n,) rad, velocities
    ``dq`` (n,) rad/s and accelerations ``ddq`` (n,) rad/s^2, with no gravity and no contact
    (Newton-Euler on the arm's model: link i a uniform box of mass ``link_mass``, centre of mass
    mid-link, inertia m (L^2 + W^2) / 12 about its joint axis; all axes parallel, so the motion
    lies in the arm's plane).  Vectorised: both recursions are cumulative sums (the same numbers as
    :func:`explore3d.feeling.localise.inverse_dynamics`, its loop form, to rounding)."""
    q, dq, ddq = (np.asarray(v, dtype=np.float64) for v in (q, dq, ddq))
    L, m = spec.link_length, spec.link_mass
    I = m * (L * L + spec.link_width ** 2) / 12.0
    th, w, al = np.cumsum(q), np.cumsum(dq), np.cumsum(ddq)
    e = np.stack([np.cos(th), np.sin(th)], axis=1)  # (n, 2) link directions, base frame
    perp = np.stack([-e[:, 1], e[:, 0]], axis=1)
    acc = L * (al[:, None] * perp - (w ** 2)[:, None] * e)  # (n, 2) joint i+1 relative to joint i
    a_o = np.cumsum(acc, axis=0) - acc  # (n, 2) acceleration of joint i's origin
    a_c = a_o + 0.5 * acc  # centre of mass, mid-link
    f = np.cumsum((m * a_c)[::-1], axis=0)[::-1]  # (n, 2) force on link i from its parent
    f_next = np.vstack([f[1:], np.zeros((1, 2))])
    # moment balance about link i's centre of mass: n_i - n_{i+1} = I al_i + r_o x f_i - r_n x f_{i+1}
    # with r_o = -(L/2) e_i, r_n = (L/2) e_i:  = I al_i + (L/2) e_i x (f_i + f_{i+1})
    s = f + f_next
    own = I * al + 0.5 * L * (e[:, 0] * s[:, 1] - e[:, 1] * s[:, 0])
    return np.cumsum(own[::-1])[::-1]


class ExternalTorque:
    """The external joint torques of one motion from what the servos report (pure numpy).

    ``tau_ext = ID(q, dq, ddq) - (tau_motor + g(q))``: the arm's model of the torques its motion
    needs (:func:`inverse_dynamics_planar`, with the sensed angles and velocities and the
    acceleration of the *commanded* reference, which the controller knows exactly where
    differentiating quantised velocities would not) less the motor torques as reported
    (feed-forward included) and the links' weights (:func:`~explore3d.arm.kinematics.gravity_torques`
    at the sensed angles, known base pose and gravity).  At rest it is
    :func:`explore3d.feeling.localise.external_torques`.  A touch of force F at a point p of link i
    gives ``z . ((p - o_j) x F)`` on joints j <= i and nothing beyond (a test checks it).

    Args:
        spec: the arm's model.
        T_world_base: (4, 4) the known base pose of the motion.
        gravity: (3,) m/s^2, world frame.
    """

    def __init__(self, spec: ArmSpec, T_world_base, gravity):
        self.spec = spec
        self.T = np.asarray(T_world_base, dtype=np.float64)
        self.gravity = np.asarray(gravity, dtype=np.float64)

    def __call__(self, q, dq, tau_motor, ddq=None) -> np.ndarray:
        """(n,) external torques, N m, at the reading (``q`` rad, ``dq`` rad/s, ``tau_motor`` N m,
        each (n,)) with the chain's acceleration ``ddq`` (n,) rad/s^2 (None: 0)."""
        q = np.asarray(q, dtype=np.float64)
        dq = np.asarray(dq, dtype=np.float64)
        ddq = np.zeros_like(q) if ddq is None else np.asarray(ddq, dtype=np.float64)
        model = inverse_dynamics_planar(self.spec, q, dq, ddq)
        return model - (np.asarray(tau_motor, dtype=np.float64) + gravity_torques(self.spec, q, self.T, self.gravity))


@dataclass(frozen=True)
class ContactBand:
    """Per-joint contact bands, rad: ``swept[j]`` bounds joint j's lag while it sweeps;
    ``other[j]`` bounds |error change| of joint j while another joint sweeps.

    ``torque[j]`` (N m; None: no torque channel, the stall detector) bounds |external torque
    change| of joint j (:class:`ExternalTorque`) while any joint sweeps and no contact found
    earlier in the attempt can load it (j beyond every joint whose sweep detected one: a contact on
    link i loads joints 0..i only); ``torque_loaded[j]`` bounds it on the joints such a contact can
    load (held links lying on the object: the reactions of the moving chain shift between their
    contacts and their motors, which the model cannot tell from a new touch).

    ``provenance``: how the bands were derived (see :func:`explore3d.world.band.calibrate_band`), a
    JSON-ready dict recorded in report.json.
    """

    swept: np.ndarray
    other: np.ndarray
    provenance: dict = field(default_factory=dict, compare=False)
    torque: np.ndarray | None = None
    torque_loaded: np.ndarray | None = None

    def __post_init__(self):
        s, o = np.asarray(self.swept, dtype=np.float64), np.asarray(self.other, dtype=np.float64)
        if s.ndim != 1 or s.shape != o.shape or not (np.isfinite(s).all() and np.isfinite(o).all()):
            raise ValueError(f"ContactBand needs finite swept and other bands of one shape (n,); got {s.shape}, {o.shape}")
        if (s < 0).any() or (o < 0).any():
            raise ValueError("ContactBand bands must be >= 0 rad")
        object.__setattr__(self, "swept", s)
        object.__setattr__(self, "other", o)
        if self.torque is not None:
            t = np.asarray(self.torque, dtype=np.float64)
            if t.shape != s.shape or not np.isfinite(t).all() or (t < 0).any():
                raise ValueError(f"ContactBand.torque must be finite, >= 0 N m, of shape {s.shape}; got {t.shape}")
            object.__setattr__(self, "torque", t)
            t = t if self.torque_loaded is None else np.asarray(self.torque_loaded, dtype=np.float64)
            if t.shape != s.shape or not np.isfinite(t).all() or (t < 0).any():
                raise ValueError(f"ContactBand.torque_loaded must be finite, >= 0 N m, of shape {s.shape}; got {t.shape}")
            object.__setattr__(self, "torque_loaded", t)

    def to_dict(self) -> dict:
        d = {"swept_rad": self.swept.tolist(), "other_rad": self.other.tolist(), "provenance": self.provenance}
        if self.torque is not None:
            d["torque_nm"] = self.torque.tolist()
            d["torque_loaded_nm"] = self.torque_loaded.tolist()
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "ContactBand":
        t, tl = d.get("torque_nm"), d.get("torque_loaded_nm")
        return cls(swept=np.asarray(d["swept_rad"], float), other=np.asarray(d["other_rad"], float),
                   provenance=dict(d.get("provenance", {})), torque=None if t is None else np.asarray(t, float),
                   torque_loaded=None if tl is None else np.asarray(tl, float))

    def torque_bands(self, loaded: int) -> np.ndarray:
        """(n,) the torque band of each joint, N m, in a sweep whose attempt detected contacts in the
        sweeps of joints up to ``loaded`` (-1: none): ``torque_loaded`` on joints 0..loaded,
        ``torque`` beyond."""
        out = self.torque.copy()
        out[: loaded + 1] = self.torque_loaded[: loaded + 1]
        return out


class SweepDetector:
    """The detection rule for one sweep of joint ``k``.

    Args:
        k: the swept joint.
        q_ref0, q0: (n,) references and readings just before the sweep, rad (the other joints'
            errors are judged against their values then).
        watch_held: also watch the held joints (< k).
        ext0: (n,) the external torques just before the sweep, N m (:class:`ExternalTorque`;
            the torque channel's changes are judged against them); None: no torque channel.
        loaded: the most distal joint whose sweep detected a contact earlier in the attempt (-1:
            none): joints 0..loaded are judged against ``ContactBand.torque_loaded``.
    """

    def __init__(self, k: int, q_ref0, q0, watch_held: bool = False, ext0=None, loaded: int = -1):
        self.loaded = int(loaded)
        self.k = int(k)
        self.base_err = np.asarray(q_ref0, dtype=np.float64) - np.asarray(q0, dtype=np.float64)
        self.watch_held = bool(watch_held)
        self._prev = None
        self.ext0 = None if ext0 is None else np.asarray(ext0, dtype=np.float64).copy()
        self._prev_ext = None
        #: (n,) the filtered external-torque change of the last update, N m (None: no torque channel)
        self.ext = None

    def update_torque(self, ext) -> np.ndarray:
        """Feed one step's external torques ``ext`` (n,), N m; returns (and keeps in :attr:`ext`)
        the mean of this and the previous step's change since the sweep began."""
        d = np.asarray(ext, dtype=np.float64) - self.ext0
        prev = self._prev_ext if self._prev_ext is not None else np.zeros_like(d)
        self._prev_ext = d
        self.ext = 0.5 * (d + prev)
        return self.ext

    def update(self, q_ref_prev_k: float, q_ref, q) -> tuple[float, np.ndarray]:
        """Feed one step: ``q_ref_prev_k`` the swept joint's reference of the previous step, rad;
        ``q_ref`` (n,) the references sent this step and ``q`` (n,) the reading after it.
        Returns the filtered (lag, error change (n,)); unwatched joints read 0."""
        k = self.k
        lag = q_ref_prev_k - q[k]
        sig = (q_ref - q) - self.base_err
        sig[k] = 0.0
        if not self.watch_held:
            sig[:k] = 0.0
        prev = self._prev if self._prev is not None else (0.0, np.zeros_like(sig))
        self._prev = (lag, sig)
        return 0.5 * (lag + prev[0]), 0.5 * (sig + prev[1])

    @staticmethod
    def _stalls(band: ContactBand, k: int, lag: float, sig) -> bool:
        """The stall rule: the swept joint's lag or another joint's error change out of its band."""
        return bool(lag > band.swept[k] or (np.abs(sig) > band.other).any())

    @staticmethod
    def exceeds(band: ContactBand, k: int, lag: float, sig, ext=None, loaded: int = -1) -> bool:
        """Whether filtered signals leave ``band`` (the contact rule); ``ext`` (n,) N m, the
        filtered external-torque change, is judged against ``band.torque_bands(loaded)`` where
        both exist."""
        if SweepDetector._stalls(band, k, lag, sig):
            return True
        return bool(ext is not None and band.torque is not None and (np.abs(ext) > band.torque_bands(loaded)).any())

    @staticmethod
    def only_loaded(band: ContactBand, k: int, lag: float, sig, ext, loaded: int) -> bool:
        """Whether signals that leave ``band`` (:meth:`exceeds`) do so only on the torque channel of
        joints 0..``loaded``, the joints behind a link already lying on the object, with the swept
        joint's lag, every error change and every more distal joint's torque in band.  A held link's
        contact loads only the joints proximal to it (``tau_ext = J^T F``), so such a change is the
        moving chain pressing the held links harder onto the object (their contact forces shifting
        against their motors), not a touch of the links the sweep carries: a new touch on link i >=
        k also reaches joints ``loaded`` + 1..i.  False when there is no torque channel or nothing
        is loaded."""
        if ext is None or band.torque is None or loaded < 0 or SweepDetector._stalls(band, k, lag, sig):
            return False
        out = np.abs(np.asarray(ext, dtype=np.float64)) > band.torque_bands(loaded)
        return bool(out[: loaded + 1].any() and not out[loaded + 1:].any())

    @staticmethod
    def ratio(band: ContactBand, k: int, lag: float, sig) -> tuple[int, float]:
        """(joint, signal / band) of the signal nearest to or furthest past its band: the
        swept joint's lag for ``k`` itself, another joint's error change otherwise."""
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(band.other > 0, np.abs(sig) / band.other, np.where(np.abs(sig) > 0, np.inf, 0.0))
            r[k] = lag / band.swept[k] if band.swept[k] > 0 else (np.inf if lag > 0 else 0.0)
        j = int(np.argmax(r))
        return j, float(r[j])
