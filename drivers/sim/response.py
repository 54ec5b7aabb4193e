"""The rig's answer to one hammer blow: a half-sine force pulse and the modal superposition of the response.

Each mode r contributes the accelerance A_rc·(-ω²)/(ω_r² - ω² + 2jζ_rω_rω) to channel c, with
A_rc = φ_r(c)·φ_r(hammer) for the mass-normalised rigid-body modes and shape·hammer/modal mass for the
disc's flexible modes. The response is the inverse FFT of that sum times the force spectrum, so an H1
estimate of the record recovers the modal FRF exactly (the responses decay long before the record ends).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
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
    """``peak·sin(π·τ/width)`` for 0 ≤ τ ≤ width, else 0; the sine is evaluated only inside the pulse (a 0.3 ms
    pulse in a 3 s record is a few samples)."""
    tau_s = np.asarray(tau_s, dtype=float)
    out = np.zeros(tau_s.shape)
    inside = (tau_s >= 0) & (tau_s <= width_s)
    out[inside] = peak_n * np.sin(np.pi * tau_s[inside] / width_s)
    return out


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
    rigid = rigid_participation(modes, channels, x_m, y_m)
    flex = flexible_participation(flexible, channels)
    return ModalModel(
        np.concatenate([np.asarray(modes.frequencies_hz, dtype=float), [fm.frequency_hz for fm in flexible]]),
        np.concatenate([np.asarray(modes.damping_ratios, dtype=float), [fm.damping_ratio for fm in flexible]]),
        np.vstack([rigid, flex]),
        tuple(channels),
    )


def rigid_participation(modes: ModesLike, channels: Sequence[str], x_m: float, y_m: float) -> np.ndarray:
    """(rigid modes × channels) A_rc = φ_r(c)·(-φ_z,r(hammer)): the hammer pushes down on the upper disc's top
    face, so the generalised force is -φ_z(hammer)·F."""
    count = len(modes.frequencies_hz)
    shapes = np.array([_row(modes.sensor_shapes(r), channels) for r in range(count)]).reshape(count, len(channels))
    at_hammer = -np.array([modes.vertical_at("upper", x_m, y_m, r) for r in range(count)])
    return shapes * at_hammer[:, None]


def flexible_participation(flexible: Sequence[FlexibleModeLike], channels: Sequence[str]) -> np.ndarray:
    """(flexible modes × channels) A_rc = shape(c)·hammer / modal mass of the disc's bending modes."""
    rows = np.array([_row(fm.shape, channels) for fm in flexible]).reshape(len(flexible), len(channels))
    scale = np.array([fm.hammer / fm.modal_mass_kg for fm in flexible])
    return rows * scale[:, None]


def _row(shape: Mapping[str, float], channels: Sequence[str]) -> list[float]:
    return list(map(shape.get, channels, [0.0] * len(channels)))


@functools.lru_cache(maxsize=8)
def _grid(n_samples: int, sample_rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """ω and ω² of a record's rfft bins (one grid per record length and rate: a campaign reuses it)."""
    w = 2.0 * np.pi * np.fft.rfftfreq(n_samples, 1.0 / sample_rate_hz)
    w.flags.writeable = False
    w2 = w**2
    w2.flags.writeable = False
    return w, w2


def _modal_frf(model: ModalModel, w: np.ndarray, w2: np.ndarray) -> np.ndarray:
    """(modes × frequencies) -ω²/(ω_r² - ω² + 2jζ_rω_rω), as real arithmetic on the real and imaginary parts."""
    wr = 2.0 * np.pi * model.frequencies_hz[:, None]
    re = wr**2 - w2[None, :]
    im = (2.0 * model.damping_ratios[:, None] * wr) * w[None, :]
    scale = -w2[None, :] / (re * re + im * im)
    out = np.empty(re.shape, dtype=complex)
    out.real = re * scale
    out.imag = -im * scale
    return out


def _combine(participation: np.ndarray, per_mode: np.ndarray) -> np.ndarray:
    """(channels × frequencies) Σ_r A_rc·X_r over the interleaved real/imaginary parts, as one ``einsum``: with a
    handful of modes a threaded BLAS product spends more CPU waking its threads than on the sum (twice the twin's
    CPU per record on a busy machine, bench/twin_speed.py)."""
    modes, bins = per_mode.shape
    flat = per_mode.view(float).reshape(modes, 2 * bins)
    return np.einsum("rc,rk->ck", participation, flat).view(complex).reshape(participation.shape[1], bins)


def accelerance(model: ModalModel, frequencies_hz: np.ndarray) -> np.ndarray:
    """(channels × frequencies) accelerance in (m/s²)/N: the truth an H1 estimate converges to."""
    w = 2.0 * np.pi * np.asarray(frequencies_hz, dtype=float)
    return _combine(model.participation, _modal_frf(model, w, w**2))


def response(model: ModalModel, force_n: np.ndarray, sample_rate_hz: float) -> np.ndarray:
    """(channels × samples) acceleration for a sampled force history: the force spectrum times each mode's FRF,
    summed over modes per channel, back by one inverse FFT over all channels."""
    n = force_n.size
    w, w2 = _grid(n, float(sample_rate_hz))
    per_mode = _modal_frf(model, w, w2)
    per_mode *= np.fft.rfft(force_n)[None, :]
    return np.fft.irfft(_combine(model.participation, per_mode), n=n, axis=1)


def digitise(signal: np.ndarray, range_units: float, bits: int) -> tuple[np.ndarray, np.ndarray]:
    """ADC quantisation over ±range and clipping; returns the samples and which rows reached the range."""
    step = 2.0 * range_units / 2.0**bits
    peak = np.abs(signal).max(axis=-1) if signal.size else np.zeros(signal.shape[:-1])
    clipped = np.atleast_1d(peak >= range_units)
    quantised = signal / step
    np.rint(quantised, out=quantised)
    quantised *= step
    return np.clip(quantised, -range_units, range_units, out=quantised), clipped
