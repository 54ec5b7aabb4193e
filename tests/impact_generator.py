"""An impact generator independent of the processing's and the twin's signal models, for tests with known truth.

Its own forms, on purpose different from ``tests/synth_impacts.py`` (frequency-domain modal superposition,
half-sine blow, noise set over the whole record):

* the rig: its own assembly of the two discs' mass and stiffness matrices (z, tilt about x, tilt about y
  of each disc; three roller springs in series with their share of K_setup; a ring support under the
  lower disc), from the rig file's numbers, and its own eigen-solution;
* the response: time-domain recursion on a grid 8× finer than the sampling, each mode's acceleration
  transfer function discretised exactly for a force linear between grid points (first-order hold), driven
  by a ``sin^1.5`` (Hertz-like) blow with a random sub-sample start; force and responses pass the same
  anti-alias filter (8th-order Butterworth at 0.4 × the sample rate) and are sampled every 8th point, as
  a DAQ samples continuous signals;
* the noise: the force's as a peak-to-noise ratio (a real hammer: 40–60 dB), the responses' as an SNR
  over the response's decay (RMS of the clean responses from the blow until the slowest contact mode's
  envelope has fallen to 1 %), white and independent on every channel;
* faults: a second blow (delay, ratio), channels clipped at a fraction of their peak in every impact.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import linalg, signal

from labctl.physics import RigConfig

FS_HZ = 20480.0
N_SAMPLES = 32768


@dataclass
class Generated:
    """An impact set (NPZ layout) and its truth."""

    fs_hz: float
    force_n: np.ndarray
    accel_m_per_s2: np.ndarray
    channels: tuple[str, ...]
    truth: dict = field(default_factory=dict)

    def save_npz(self, path) -> None:
        np.savez(path, fs=np.float64(self.fs_hz), force=self.force_n, accel=self.accel_m_per_s2,
                 channels=np.array(self.channels, dtype=str))


def _matrices(rig: RigConfig, k: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Mass and stiffness over q = (z_u, θx_u, θy_u, z_l, θx_l, θy_l) from the potential energy."""
    m = np.diag([rig.upper.mass_kg, rig.upper.inertia_kg_m2, rig.upper.inertia_kg_m2,
                 rig.lower.mass_kg, rig.lower.inertia_kg_m2, rig.lower.inertia_kg_m2])
    kk = np.zeros((6, 6))
    for ki, ang in zip(k, rig.contact_angles_rad, strict=True):
        x, y = rig.contact_radius_m * math.cos(ang), rig.contact_radius_m * math.sin(ang)
        path = 1.0 / (1.0 / ki + 3.0 / rig.setup_stiffness_n_per_m)
        # the approach at the contact: vertical motion of the upper disc's point minus the lower disc's
        a = np.array([1.0, y, -x, -1.0, -y, x])
        kk += path * np.outer(a, a)
    ks, r = rig.support_stiffness_n_per_m, rig.support_radius_m
    kk[3, 3] += ks
    # a ring of total stiffness ks at radius r: ∫ (θ r sinφ)² ks dφ/2π = ks r² θ² / 2
    kk[4, 4] += 0.5 * ks * r * r
    kk[5, 5] += 0.5 * ks * r * r
    return m, kk


def _vertical(q: np.ndarray, disc: str, x: float, y: float) -> float:
    o = 0 if disc == "upper" else 3
    return float(q[o] + q[o + 1] * y - q[o + 2] * x)


def _channel_gain(q: np.ndarray, rig: RigConfig, channel: str) -> float:
    """Displacement along a channel's axis for the DOF vector q (X radial, Y tangential, Z vertical)."""
    for s in rig.sensors:
        if channel.startswith(s.name) and channel[len(s.name):] in ("X", "Y", "Z"):
            o = 0 if s.disc == "upper" else 3
            rx, ry = q[o + 1], q[o + 2]
            ux, uy = ry * s.z_m, -rx * s.z_m
            axis = channel[-1]
            if axis == "Z":
                return _vertical(q, s.disc, s.x_m, s.y_m)
            c, sn = math.cos(s.angle_rad), math.sin(s.angle_rad)
            return float(c * ux + sn * uy) if axis == "X" else float(-sn * ux + c * uy)
    raise KeyError(channel)


def rig_eigen(rig: RigConfig, k: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Natural frequencies (Hz, ascending) and mass-normalised shapes (6, 6)."""
    m, kk = _matrices(rig, k)
    w2, phi = linalg.eigh(kk, m)
    return np.sqrt(np.clip(w2, 0, None)) / (2 * math.pi), phi


def contact_truth(rig: RigConfig, k: Sequence[float]) -> dict:
    """Bounce (the mode with the largest mean approach) and the tilt pair of the generator's own model."""
    f, phi = rig_eigen(rig, k)
    rows = [np.array([1.0, rig.contact_radius_m * math.sin(a), -rig.contact_radius_m * math.cos(a),
                      -1.0, -rig.contact_radius_m * math.sin(a), rig.contact_radius_m * math.cos(a)])
            for a in rig.contact_angles_rad]
    contact = [3, 4, 5]
    score = [abs(np.mean([r @ phi[:, i] for r in rows])) / np.sqrt(np.mean([(r @ phi[:, i]) ** 2 for r in rows]))
             for i in contact]
    b = contact[int(np.argmax(score))]
    tilt = sorted(float(f[i]) for i in contact if i != b)
    return {"bounce_hz": float(f[b]), "tilt_hz": tilt, "bounce_index": b}


def _pulse(n: int, fs: float, start_s: float, width_s: float, peak: float) -> np.ndarray:
    t = np.arange(n) / fs - start_s
    x = np.clip(t / width_s, 0.0, 1.0)
    return peak * np.where((t > 0) & (t < width_s), np.sin(np.pi * x) ** 1.5, 0.0)


def generate(
    rig: RigConfig,
    k: float | Sequence[float],
    *,
    channels: Sequence[str] | None = None,
    zeta: float = 0.018,
    n_impacts: int = 3,
    fs_hz: float = FS_HZ,
    n_samples: int = N_SAMPLES,
    snr_db: float = 40.0,
    force_snr_db: float = 50.0,
    width_s: float = 2.5e-4,
    peak_n: float | Sequence[float] = 250.0,
    second_hit: tuple[float, float] | None = None,
    clip: dict[str, float] | None = None,
    k_per_impact: Sequence[Sequence[float]] | None = None,
    seed: int = 0,
) -> Generated:
    """Impacts on the rig with roller stiffness(es) ``k`` (``k_per_impact`` overrides them blow by blow).

    ``second_hit`` = (delay s, ratio) on every impact; ``clip`` maps a channel to the fraction of its
    peak where it saturates, in every impact.
    """
    rng = np.random.default_rng(seed)
    chans = tuple(channels or rig.channels)
    ks = [float(v) for v in np.broadcast_to(np.asarray(k, float), (3,))]
    peaks = np.broadcast_to(np.asarray(peak_n, float), (n_impacts,))
    hx, hy = rig.hammer_xy_m
    dt = 1.0 / fs_hz
    force = np.zeros((n_impacts, n_samples))
    accel = np.zeros((n_impacts, len(chans), n_samples))
    start = 200
    decay_end = n_samples
    over = 8
    anti_alias = signal.butter(8, 0.4 * fs_hz, fs=fs_hz * over, output="sos")
    for i in range(n_impacts):
        ki = ks if k_per_impact is None else [float(v) for v in k_per_impact[i]]
        freqs, phi = rig_eigen(rig, ki)
        t0 = (start + rng.uniform(0, 1)) * dt
        f = _pulse(n_samples * over, fs_hz * over, t0, width_s, peaks[i])
        if second_hit is not None:
            f += _pulse(n_samples * over, fs_hz * over, t0 + second_hit[0], width_s, second_hit[1] * peaks[i])
        f = signal.sosfilt(anti_alias, f)  # the responses follow from the filtered force: both channels filtered
        for r in range(6):
            w = 2 * math.pi * freqs[r]
            z = rig.support_damping_ratio if r < 3 else zeta
            num, den, _ = signal.cont2discrete(([1.0, 0.0, 0.0], [1.0, 2 * z * w, w * w]), dt / over, method="foh")
            modal = signal.lfilter(np.ravel(num), den, f)[::over]
            at_hammer = _vertical(phi[:, r], "upper", hx, hy)
            gains = np.array([_channel_gain(phi[:, r], rig, c) for c in chans])
            accel[i] += np.outer(-gains * at_hammer, modal)  # a downward blow on the top face
        force[i] = f[::over]
        slowest = min(freqs[3:]) * 2 * math.pi * zeta
        decay_end = min(decay_end, start + int(math.log(100.0) / slowest * fs_hz))
    clean_rms = float(np.sqrt(np.mean(accel[:, :, start:decay_end] ** 2)))
    sigma_a = clean_rms / 10 ** (snr_db / 20)
    sigma_f = float(np.max(peaks)) / 10 ** (force_snr_db / 20)
    accel += rng.normal(0.0, sigma_a, accel.shape)
    force += rng.normal(0.0, sigma_f, force.shape)
    for ch, frac in (clip or {}).items():
        c = chans.index(ch)
        for i in range(n_impacts):
            level = frac * float(np.abs(accel[i, c]).max())
            accel[i, c] = np.clip(accel[i, c], -level, level)
    truth = contact_truth(rig, ks)
    truth.update({"roller_stiffness_n_per_m": ks, "noise_m_per_s2": sigma_a, "noise_n": sigma_f})
    return Generated(fs_hz, force, accel, chans, truth)
