"""What a real servo reports: quantised, noisy, one control step late.

:class:`SensorConfig` states the sensing (SI units); :class:`Sensors` turns the simulator's exact
joint state into what the controller reads.  Every random draw comes from a numpy Generator the
caller seeds per wrap (``Sensors.reseed``), so an exploration gives the same readings for any
number of worker processes.

Defaults: a 4096-count-per-turn encoder (a 12-bit magnetic encoder, as in common hobby and
research servos), joint velocity in units of 0.229 rpm (0.024 rad/s, a Dynamixel's velocity unit),
motor torque from the current sensor at 1 mN m resolution with 1 mN m (1 sigma) noise, and one
control step of delay between measuring and the controller receiving the reading.
"""
from __future__ import annotations

import dataclasses
import math
from collections import deque
from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["SensorConfig", "Sensors", "IDEAL_SENSING"]


@dataclass(frozen=True)
class SensorConfig:
    """Joint sensing of every servo (SI units).

    Attributes:
        encoder_counts_per_turn: angle resolution, counts per 2 pi rad (0: exact angles).
        angle_noise_rad: Gaussian noise on the angle before quantisation, rad (1 sigma).
        velocity_resolution_rad_s: joint velocity resolution, rad/s (0: exact).
        velocity_noise_rad_s: Gaussian noise on the velocity, rad/s (1 sigma).
        torque_resolution_nm: motor torque resolution, N m (0: exact).
        torque_noise_nm: Gaussian noise on the motor torque, N m (1 sigma).
        delay_steps: control steps between a measurement and the controller reading it (>= 0).
        seed: base seed of the noise; each wrap draws from ``(seed, wrap index)``.
    """

    encoder_counts_per_turn: int = 4096
    angle_noise_rad: float = 0.0
    velocity_resolution_rad_s: float = 0.229 * 2.0 * math.pi / 60.0
    velocity_noise_rad_s: float = 0.0
    torque_resolution_nm: float = 1.0e-3
    torque_noise_nm: float = 1.0e-3
    delay_steps: int = 1
    seed: int = 0

    def __post_init__(self):
        for name in ("encoder_counts_per_turn", "delay_steps", "seed"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 0:
                raise ValueError(f"SensorConfig.{name} must be an integer >= 0; got {v!r}")
        for name in ("angle_noise_rad", "velocity_resolution_rad_s", "velocity_noise_rad_s",
                     "torque_resolution_nm", "torque_noise_nm"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0):
                raise ValueError(f"SensorConfig.{name} must be a finite number >= 0; got {v!r}")

    @classmethod
    def ideal(cls) -> "SensorConfig":
        """Exact angles, velocities and torques, no delay (the idealised simulation)."""
        return cls(encoder_counts_per_turn=0, angle_noise_rad=0.0, velocity_resolution_rad_s=0.0,
                   velocity_noise_rad_s=0.0, torque_resolution_nm=0.0, torque_noise_nm=0.0, delay_steps=0)

    @property
    def is_ideal(self) -> bool:
        """Exact readings with no delay (the seed is then irrelevant)."""
        return dataclasses.replace(self, seed=0) == SensorConfig.ideal()

    @property
    def angle_resolution_rad(self) -> float:
        """One encoder count, rad (0 for exact angles)."""
        return 0.0 if self.encoder_counts_per_turn == 0 else 2.0 * math.pi / self.encoder_counts_per_turn

    def to_dict(self) -> dict:
        return asdict(self)


#: Exact sensing, no delay.
IDEAL_SENSING = SensorConfig.ideal()


def _quantise(x: np.ndarray, res: float) -> np.ndarray:
    return x if res <= 0 else np.round(x / res) * res


class Sensors:
    """Turns exact joint states into readings: noise, quantisation, then ``delay_steps`` of delay.

    ``measure(q, dq, tau)`` takes the exact state after a physics step and returns the reading the
    controller receives at that step (the one measured ``delay_steps`` steps earlier).
    ``restart(q, dq, tau)`` fills the delay line with a state at rest (the start of a motion).
    """

    def __init__(self, config: SensorConfig):
        self.config = config
        self._rng = np.random.default_rng(config.seed)
        self._line: deque = deque()

    def reseed(self, key) -> None:
        """Seed the noise with ``(config.seed, *key)`` (e.g. key = (wrap index,))."""
        self._rng = np.random.default_rng([self.config.seed, *[int(k) for k in key]])

    def _read(self, q, dq, tau):
        c = self.config
        n = len(q)
        if c.angle_noise_rad:
            q = q + self._rng.normal(0.0, c.angle_noise_rad, n)
        if c.velocity_noise_rad_s:
            dq = dq + self._rng.normal(0.0, c.velocity_noise_rad_s, n)
        if c.torque_noise_nm:
            tau = tau + self._rng.normal(0.0, c.torque_noise_nm, n)
        return (_quantise(q, c.angle_resolution_rad), _quantise(dq, c.velocity_resolution_rad_s),
                _quantise(tau, c.torque_resolution_nm))

    def restart(self, q, dq, tau):
        r = self._read(q, dq, tau)
        self._line = deque([r] * (self.config.delay_steps + 1), maxlen=self.config.delay_steps + 1)
        return r

    def measure(self, q, dq, tau):
        self._line.append(self._read(q, dq, tau))
        return self._line[0]
