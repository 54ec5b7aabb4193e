"""The rig's answer to one hammer blow: a half-sine force pulse and the modal superposition of the response.

Each mode r contributes the accelerance A_rc·(-ω²)/(ω_r² - ω² + 2jζ_rω_rω) to channel c, with
A_rc = φ_r(c)·φ_r(hammer) for the mass-normalised rigid-body modes and shape·hammer/modal mass for the
disc's flexible modes. The response is the inverse FFT of that sum times the force spectrum, so an H1
estimate of the record recovers the modal FRF exactly (the responses decay long before the record ends).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from drivers.sim.model import FlexibleModeLike, ModesLike


@dataclass(frozen=True)
class Blow:
    """One hammer blow: peak force, pulse width, impact point on the upper disc, optional second hit."""

    peak_n: float
    width_s: float
    x_m: float
    y_m: float
    second_delay_s: float = 0.0  # 0: a clean single hit
    second_ratio: float = 0.0

    def force_n(self, t_s: np.ndarray, onset_s: float) -> np.ndarray:
        """Force history sampled at ``t_s`` for a first pulse starting at ``onset_s``."""
        out = _half_sine(t_s - onset_s, self.width_s, self.peak_n)
        if self.second_delay_s > 0 and self.second_ratio > 0:
            out += _half_sine(t_s - onset_s - self.second_delay_s, self.width_s, self.peak_n * self.second_ratio)
        return out

    def impulse_n_s(self) -> float:
        """∫F dt of the blow (both pulses)."""
        return 2.0 / math.pi * self.width_s * self.peak_n * (1.0 + self.second_ratio)

    def onset_s(self, crossing_s: float, level_n: float) -> float:
        """Pulse start such that the rising force crosses ``level_n`` at ``crossing_s``."""
        return crossing_s - self.width_s / math.pi * math.asin(min(1.0, level_n / self.peak_n))


def _half_sine(tau_s: np.ndarray, width_s: float, peak_n: float) -> np.ndarray:
    inside = (tau_s >= 0) & (tau_s <= width_s)
    return np.where(inside, peak_n * np.sin(np.pi * np.clip(tau_s, 0.0, width_s) / width_s), 0.0)


@dataclass(frozen=True)
class ModalModel:
    """Frequencies (Hz), damping ratios and participation A (modes × channels) for one impact point."""

    frequencies_hz: np.ndarray
    damping_ratios: np.ndarray
    participation: np.ndarray
    channels: tuple[str, ...]


def modal_model(
    modes: ModesLike, flexible: Sequence[FlexibleModeLike], channels: Sequence[str], x_m: float, y_m: float
) -> ModalModel:
    """Rigid-body modes from the rig model plus the rig file's flexible modes, for a blow at (x, y)."""
    freqs, zetas, rows = [], [], []
    for r, (f, z) in enumerate(zip(modes.frequencies_hz, modes.damping_ratios, strict=True)):
        shape = modes.sensor_shapes(r)
        # the hammer pushes down on the upper disc's top face: generalised force -φ_z(hammer)·F
        at_hammer = -modes.vertical_at("upper", x_m, y_m, r)
        freqs.append(float(f))
        zetas.append(float(z))
        rows.append([shape.get(ch, 0.0) * at_hammer for ch in channels])
    for fm in flexible:
        freqs.append(fm.frequency_hz)
        zetas.append(fm.damping_ratio)
        rows.append([fm.shape.get(ch, 0.0) * fm.hammer / fm.modal_mass_kg for ch in channels])
    return ModalModel(np.array(freqs), np.array(zetas), np.array(rows), tuple(channels))


def accelerance(model: ModalModel, frequencies_hz: np.ndarray) -> np.ndarray:
    """(channels × frequencies) accelerance in (m/s²)/N: the truth an H1 estimate converges to."""
    w = 2.0 * np.pi * np.asarray(frequencies_hz, dtype=float)[None, :]
    wr = 2.0 * np.pi * model.frequencies_hz[:, None]
    per_mode = -(w**2) / (wr**2 - w**2 + 2j * model.damping_ratios[:, None] * wr * w)
    return model.participation.T @ per_mode


def response(model: ModalModel, force_n: np.ndarray, sample_rate_hz: float) -> np.ndarray:
    """(channels × samples) acceleration for a sampled force history."""
    n = force_n.size
    spectrum = np.fft.rfft(force_n)
    h = accelerance(model, np.fft.rfftfreq(n, 1.0 / sample_rate_hz))
    return np.fft.irfft(h * spectrum[None, :], n=n, axis=1)


def digitise(signal: np.ndarray, range_units: float, bits: int) -> tuple[np.ndarray, np.ndarray]:
    """ADC quantisation over ±range and clipping; returns the samples and which rows reached the range."""
    step = 2.0 * range_units / 2.0**bits
    quantised = np.round(signal / step) * step
    clipped = np.atleast_2d(np.abs(signal) >= range_units).any(axis=-1)
    return np.clip(quantised, -range_units, range_units), clipped
