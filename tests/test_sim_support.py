"""Helpers shared by the simulator tests (no tests here): a simulated rig, and an H1 estimate written with
numpy alone, independent of labctl's processing."""

from __future__ import annotations

import numpy as np

from drivers.interfaces import Rig, TriggerSpec
from labctl.backends import make_rig
from labctl.physics import ContactCase, material, roller

STEEL = material("1.3505")


def sim_rig(roller_type: int = 1, seed: int | None = 7, **kw) -> Rig:
    """The simulated paper rig with a catalogue roller on Ra 0.2 µm steel rails."""
    return make_rig("sim", case=ContactCase(roller(roller_type), STEEL, 0.2e-6), seed=seed, **kw)


def strike_records(rig: Rig, n: int = 3, fs: float = 20_480.0, samples: int = 65_536) -> list:
    """Configure, then arm/strike/acquire ``n`` times through the instrument interfaces."""
    rig.daq.configure(fs, samples)
    out = []
    for _ in range(n):
        rig.daq.arm(TriggerSpec())
        rig.hammer.strike()
        out.append(rig.daq.acquire(timeout_s=1.0))
    return out


def h1(force: np.ndarray, accel: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """Averaged H1 = Σ conj(F)·A / Σ |F|² over impacts: (frequencies, channels × frequencies)."""
    f_spec = np.fft.rfft(np.atleast_2d(force), axis=-1)
    a_spec = np.fft.rfft(accel.reshape(f_spec.shape[0], -1, force.shape[-1]), axis=-1)
    num = (np.conj(f_spec)[:, None, :] * a_spec).sum(axis=0)
    return np.fft.rfftfreq(force.shape[-1], 1.0 / fs), num / (np.abs(f_spec) ** 2).sum(axis=0)


def peak_hz(freqs: np.ndarray, frf: np.ndarray, lo: float, hi: float) -> float:
    band = (freqs > lo) & (freqs < hi)
    return float(freqs[band][np.argmax(np.abs(frf[band]))])


def bounce_and_tilt_peaks(freqs: np.ndarray, frf: np.ndarray, channels: list[str]) -> tuple[float, float]:
    """Bounce: the top discs' vertical channels in phase; tilt: roller 1 against the mean of rollers 2 and 3."""
    z1, z2, z3 = (frf[channels.index(c)] for c in ("A1Z", "A2Z", "A3Z"))
    return peak_hz(freqs, z1 + z2 + z3, 200, 1500), peak_hz(freqs, z1 - 0.5 * (z2 + z3), 200, 1500)


def pulse_width_s(force: np.ndarray, fs: float) -> float:
    """Half-sine width from its area and peak (area = 2·peak·T/π) over the samples above 2 % of the peak."""
    i = int(np.argmax(force))
    peak = force[i]
    lo, hi = i, i
    while lo > 0 and force[lo - 1] > 0.02 * peak:
        lo -= 1
    while hi < force.size - 1 and force[hi + 1] > 0.02 * peak:
        hi += 1
    area = force[lo: hi + 1].sum() / fs
    return float(np.pi * area / (2.0 * peak))
