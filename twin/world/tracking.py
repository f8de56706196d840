"""A sluggish, noisy joint controller (`robot.tracking_*`, a fault model) between the commands and the motors."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from twin.config import Settings

__all__ = ["FaultyTracking"]


@dataclass
class FaultyTracking:
    """The state of a sluggish, noisy joint controller (`robot.tracking_*`, a fault model)."""

    alpha: float  # the share of the remaining gap the lagged target closes per physics step
    noise_rad: float
    rng: np.random.Generator
    commanded: np.ndarray = field(default_factory=lambda: np.zeros(6))
    lagged: np.ndarray = field(default_factory=lambda: np.zeros(6))

    @classmethod
    def from_settings(cls, settings: Settings, seed: int, dt: float) -> FaultyTracking | None:
        """The controller of `settings`, its noise stream drawn from the scene seed; None for the ideal one."""
        r = settings.robot
        if r.tracking_time_constant_s == 0 and r.tracking_noise_rad == 0:
            return None  # the ideal controller: targets go to the motors as commanded
        tau = r.tracking_time_constant_s
        alpha = 1.0 if tau == 0 else 1.0 - math.exp(-dt / tau)
        return cls(alpha, r.tracking_noise_rad, np.random.default_rng([seed, 0x7AC]))

    def advance(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """One physics step: the target it sends follows the commanded one through a first-order lag, plus
        noise; the velocity feed-forward is its rate. Returns (target (6,), feed-forward (6,))."""
        previous = self.lagged.copy()
        self.lagged += self.alpha * (self.commanded - self.lagged)
        target = self.lagged + (self.rng.normal(0.0, self.noise_rad, 6) if self.noise_rad > 0 else 0.0)
        return target, (self.lagged - previous) / dt
