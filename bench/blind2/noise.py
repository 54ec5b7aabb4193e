"""Measurement noise of the second judge: set by the bounce frequency's resolution and the hammer's force level.

σ_f = 2·Δf/f: k ∝ f², and the peak of the bounce mode f = √(6k/m)/2π is located to Δf (leakage, damping);
σ_h = ½·(F_dyn/F)·|d ln k/d ln F|: the blow's dynamic load F_dyn per roller samples the curved F(δ) around F.
Per point σ = √(σ_f² + σ_h²), drawn Student-t (ν 4-8, rescaled to unit variance); a seating offset per repetition.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class NoiseModel:
    """Drawn rig/noise constants (all before the noise scale)."""

    disc_mass_kg: float
    delta_f_hz: float
    f_dyn_n: float
    nu: float
    seat_sigma: float

    @classmethod
    def draw(cls, rng: np.random.Generator) -> NoiseModel:
        return cls(
            disc_mass_kg=float(rng.uniform(18.0, 24.0)),
            delta_f_hz=float(rng.uniform(0.6, 2.0)),
            f_dyn_n=float(rng.uniform(5.0, 15.0)),
            nu=float(rng.uniform(4.0, 8.0)),
            seat_sigma=float(rng.uniform(0.003, 0.01)),
        )

    def point_sigma(self, k: np.ndarray, load_n: np.ndarray, log_slope: np.ndarray) -> np.ndarray:
        """Relative 1-σ of one point (without the seating term)."""
        f = np.sqrt(6.0 * k / self.disc_mass_kg) / (2.0 * np.pi)
        s_f = 2.0 * self.delta_f_hz / f
        s_h = 0.5 * (self.f_dyn_n / load_n) * np.abs(log_slope)
        return np.sqrt(s_f**2 + s_h**2)

    def total_sigma(self, k: np.ndarray, load_n: np.ndarray, log_slope: np.ndarray) -> np.ndarray:
        """Relative 1-σ including the seating random effect."""
        return np.sqrt(self.point_sigma(k, load_n, log_slope) ** 2 + self.seat_sigma**2)

    def sample(self, rng: np.random.Generator, k: np.ndarray, load_n: np.ndarray, log_slope: np.ndarray,
               scale: float) -> np.ndarray:
        """Multiplicative noise exp(ε) for points shaped (n_cfg, reps, steps)."""
        t = rng.standard_t(self.nu, size=k.shape) * np.sqrt((self.nu - 2.0) / self.nu)
        seat = rng.normal(0.0, self.seat_sigma, size=k.shape[:2] + (1,))
        return np.exp(scale * (t * self.point_sigma(k, load_n, log_slope) + seat))


def log_slope(k: np.ndarray, load_n: np.ndarray) -> np.ndarray:
    """d ln k / d ln F along the last axis (the load steps)."""
    return np.gradient(np.log(k), axis=-1) / np.gradient(np.log(load_n), axis=-1)
