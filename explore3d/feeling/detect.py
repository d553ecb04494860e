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
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["ContactBand", "SweepDetector"]


@dataclass(frozen=True)
class ContactBand:
    """Per-joint contact bands, rad: ``swept[j]`` bounds joint j's lag while it sweeps;
    ``other[j]`` bounds |error change| of joint j while another joint sweeps.

    ``provenance``: how the bands were derived (see :func:`explore3d.world.band.calibrate_band`), a
    JSON-ready dict recorded in report.json.
    """

    swept: np.ndarray
    other: np.ndarray
    provenance: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        s, o = np.asarray(self.swept, dtype=np.float64), np.asarray(self.other, dtype=np.float64)
        if s.ndim != 1 or s.shape != o.shape or not (np.isfinite(s).all() and np.isfinite(o).all()):
            raise ValueError(f"ContactBand needs finite swept and other bands of one shape (n,); got {s.shape}, {o.shape}")
        if (s < 0).any() or (o < 0).any():
            raise ValueError("ContactBand bands must be >= 0 rad")
        object.__setattr__(self, "swept", s)
        object.__setattr__(self, "other", o)

    def to_dict(self) -> dict:
        return {"swept_rad": self.swept.tolist(), "other_rad": self.other.tolist(), "provenance": self.provenance}

    @classmethod
    def from_dict(cls, d: dict) -> "ContactBand":
        return cls(swept=np.asarray(d["swept_rad"], float), other=np.asarray(d["other_rad"], float),
                   provenance=dict(d.get("provenance", {})))


class SweepDetector:
    """The detection rule for one sweep of joint ``k``.

    Args:
        k: the swept joint.
        q_ref0, q0: (n,) references and readings just before the sweep, rad (the other joints'
            errors are judged against their values then).
        watch_held: also watch the held joints (< k).
    """

    def __init__(self, k: int, q_ref0, q0, watch_held: bool = False):
        self.k = int(k)
        self.base_err = np.asarray(q_ref0, dtype=np.float64) - np.asarray(q0, dtype=np.float64)
        self.watch_held = bool(watch_held)
        self._prev = None

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
    def exceeds(band: ContactBand, k: int, lag: float, sig) -> bool:
        """Whether filtered signals leave ``band`` (the contact rule)."""
        return bool(lag > band.swept[k] or (np.abs(sig) > band.other).any())

    @staticmethod
    def ratio(band: ContactBand, k: int, lag: float, sig) -> tuple[int, float]:
        """(joint, signal / band) of the signal nearest to or furthest past its band: the
        swept joint's lag for ``k`` itself, another joint's error change otherwise."""
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(band.other > 0, np.abs(sig) / band.other, np.where(np.abs(sig) > 0, np.inf, 0.0))
            r[k] = lag / band.swept[k] if band.swept[k] > 0 else (np.inf if lag > 0 else 0.0)
        j = int(np.argmax(r))
        return j, float(r[j])
