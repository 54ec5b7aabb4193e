"""Synthetic impact sets with known truth: modal superposition of the rig's modes driven by a half-sine blow.

Independent of the simulated rig backend on purpose: the processing is tested (and benchmarked) against a
signal model whose every parameter is known. The accelerance of mode r at channel c is
``s²·R_rc / (s² + 2ζ_r Ω_r s + Ω_r²)`` with a real modal constant ``R_rc`` (proportional damping); the
response is synthesised in the frequency domain on a doubled record, so the measured record contains no
wrap-around. Noise levels are set by an SNR in dB: the noise RMS is the clean signal's RMS over the record
(all accelerometer channels together, and the force on its own) divided by 10^(SNR/20).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import signal

from labctl.physics import RigConfig, load_rig, rig_modes

FS_HZ = 20480.0
N_SAMPLES = 65536


@dataclass(frozen=True)
class SynthMode:
    """One mode of the synthetic structure: its modal constant per channel for a unit downward blow."""

    kind: str
    frequency_hz: float
    damping_ratio: float
    residue: np.ndarray  # (n_channels,) m/s² per N in the accelerance's high-frequency limit


@dataclass
class SynthSet:
    """An impacts set in the NPZ contract's layout plus the truth it was made from."""

    fs_hz: float
    force_n: np.ndarray
    accel_m_per_s2: np.ndarray
    channels: tuple[str, ...]
    modes: list[SynthMode]
    truth: dict = field(default_factory=dict)

    def save_npz(self, path: str | Path) -> Path:
        np.savez(path, fs=np.float64(self.fs_hz), force=self.force_n, accel=self.accel_m_per_s2,
                 channels=np.array(self.channels, dtype=str))
        return Path(path)


def rig_truth_modes(
    rig: RigConfig,
    roller_stiffness_n_per_m: float | Sequence[float],
    channels: Sequence[str] | None = None,
    *,
    hammer_xy_m: tuple[float, float] | None = None,
    damping_ratios: Sequence[float] | None = None,
    flexible: bool = True,
) -> list[SynthMode]:
    """The rig's support, contact and flexible modes as seen by ``channels`` for a blow at ``hammer_xy_m``.

    ``damping_ratios`` overrides the three contact modes' damping (tilt, tilt, bounce order of rig_modes).
    """
    modes = rig_modes(rig, roller_stiffness_n_per_m)
    chans = tuple(channels or rig.channels)
    hx, hy = hammer_xy_m or rig.hammer_xy_m
    out: list[SynthMode] = []
    contact = [modes.tilt[0], modes.tilt[1], modes.bounce]
    for i in range(len(modes.frequencies_hz)):
        shape = modes.sensor_shapes(i)
        at_hammer = modes.vertical_at("upper", hx, hy, i)
        residue = np.array([-shape[c] * at_hammer for c in chans])  # downward blow on the top face
        zeta = float(modes.damping_ratios[i])
        if damping_ratios is not None and i in contact:
            zeta = float(damping_ratios[contact.index(i)])
        kind = "bounce" if i == modes.bounce else "tilt" if i in modes.tilt else "support"
        out.append(SynthMode(kind, float(modes.frequencies_hz[i]), zeta, residue))
    if flexible:
        for fm in rig.flexible_modes:
            residue = np.array([-fm.shape.get(c, 0.0) * fm.hammer / fm.modal_mass_kg for c in chans])
            out.append(SynthMode("flexible", fm.frequency_hz, fm.damping_ratio, residue))
    return out


def accelerance(modes: Sequence[SynthMode], freqs_hz: np.ndarray) -> np.ndarray:
    """(n_channels, n_freqs) complex accelerance of the modal model."""
    s = 2j * np.pi * np.asarray(freqs_hz)
    out = np.zeros((len(modes[0].residue), len(s)), dtype=complex)
    for m in modes:
        w = 2 * np.pi * m.frequency_hz
        out += np.outer(m.residue, s**2 / (s**2 + 2 * m.damping_ratio * w * s + w**2))
    return out


def half_sine(n: int, fs_hz: float, start_s: float, width_s: float, peak_n: float) -> np.ndarray:
    t = np.arange(n) / fs_hz - start_s
    inside = (t >= 0) & (t <= width_s)
    return np.where(inside, peak_n * np.sin(np.pi * np.clip(t, 0, width_s) / width_s), 0.0)


def synth_impacts(
    modes: Sequence[SynthMode] | Sequence[Sequence[SynthMode]],
    channels: Sequence[str],
    *,
    fs_hz: float = FS_HZ,
    n_samples: int = N_SAMPLES,
    n_impacts: int = 3,
    snr_db: float = 40.0,
    pulse_s: float | Sequence[float] = 3e-4,
    peak_force_n: float | Sequence[float] = 300.0,
    pretrigger: int = 256,
    double_hits: dict[int, tuple[float, float]] | None = None,
    clip: dict[int, tuple[str, float]] | None = None,
    dead: Sequence[str] = (),
    ringing: bool = False,
    seed: int = 0,
    snr_decay_s: float | None = None,
    force_peak_snr_db: float | None = None,
) -> SynthSet:
    """Impacts of the modal model; ``modes`` may be one list or one list per impact (hit-point scatter).

    ``double_hits`` maps an impact index to (delay s, ratio of the second peak); ``clip`` maps an impact
    index to (channel, level m/s²) where that channel saturates; ``dead`` channels read exactly zero;
    ``ringing`` passes every channel through a sharp anti-alias filter (as a DAQ does).
    ``snr_decay_s``: the responses' SNR is taken over this long after the blow (the response's decay)
    instead of the whole record; ``force_peak_snr_db``: the force noise as peak to noise (a real hammer's
    40-60 dB) instead of the force's RMS over the record at ``snr_db``.
    """
    rng = np.random.default_rng(seed)
    per_impact = [list(modes)] * n_impacts if isinstance(modes[0], SynthMode) else [list(m) for m in modes]
    widths = np.broadcast_to(np.asarray(pulse_s, float), (n_impacts,))
    peaks = np.broadcast_to(np.asarray(peak_force_n, float), (n_impacts,))
    n_pad = 2 * n_samples
    freqs = np.fft.rfftfreq(n_pad, 1.0 / fs_hz)
    force = np.zeros((n_impacts, n_samples))
    accel = np.zeros((n_impacts, len(channels), n_samples))
    sos = signal.ellip(8, 0.05, 90, 0.42 * fs_hz, fs=fs_hz, output="sos") if ringing else None
    for i in range(n_impacts):
        start = (pretrigger + rng.uniform(0.0, 1.0)) / fs_hz
        f = half_sine(n_pad, fs_hz, start, widths[i], peaks[i])
        if double_hits and i in double_hits:
            delay, ratio = double_hits[i]
            f += half_sine(n_pad, fs_hz, start + delay, widths[i], ratio * peaks[i])
        if sos is not None:
            f = signal.sosfilt(sos, f)
        y = np.fft.irfft(accelerance(per_impact[i], freqs) * np.fft.rfft(f), n_pad, axis=-1)
        force[i], accel[i] = f[:n_samples], y[:, :n_samples]
    if snr_decay_s is None:
        sigma_a = math.sqrt(np.mean(accel**2)) / 10 ** (snr_db / 20)
    else:
        end = pretrigger + int(snr_decay_s * fs_hz)
        sigma_a = math.sqrt(np.mean(accel[:, :, pretrigger:end] ** 2)) / 10 ** (snr_db / 20)
    if force_peak_snr_db is None:
        sigma_f = math.sqrt(np.mean(force**2)) / 10 ** (snr_db / 20)
    else:
        sigma_f = float(np.max(np.abs(force))) / 10 ** (force_peak_snr_db / 20)
    accel += rng.normal(0.0, sigma_a, accel.shape)
    force += rng.normal(0.0, sigma_f, force.shape)
    for i, (ch, level) in (clip or {}).items():
        c = list(channels).index(ch)
        accel[i, c] = np.clip(accel[i, c], -level, level)
    for ch in dead:
        accel[:, list(channels).index(ch)] = 0.0
    return SynthSet(fs_hz, force, accel, tuple(channels), per_impact[0],
                    {"noise_m_per_s2": sigma_a, "noise_n": sigma_f})


def rig_set(
    k: float | Sequence[float] = 4.65e7,
    *,
    rig: RigConfig | None = None,
    channels: Sequence[str] | None = None,
    damping_ratios: Sequence[float] | None = None,
    hit_scatter_m: float = 0.0,
    n_impacts: int = 3,
    seed: int = 0,
    **kw,
) -> SynthSet:
    """A rig impact set at roller stiffness(es) ``k`` with its truth (bounce, tilt pair, stiffness)."""
    rig = rig or load_rig()
    chans = tuple(channels or rig.channels)
    rng = np.random.default_rng(seed + 10_000)
    hx, hy = rig.hammer_xy_m
    hits = [(hx + rng.normal(0, hit_scatter_m), hy + rng.normal(0, hit_scatter_m)) for _ in range(n_impacts)]
    per_impact = [rig_truth_modes(rig, k, chans, hammer_xy_m=xy, damping_ratios=damping_ratios) for xy in hits]
    out = synth_impacts(per_impact, chans, n_impacts=n_impacts, seed=seed, **kw)
    contact = {m.kind: m for m in out.modes if m.kind == "bounce"}
    tilt = sorted(m.frequency_hz for m in out.modes if m.kind == "tilt")
    ks = np.broadcast_to(np.asarray(k, float), (3,))
    out.truth.update({
        "bounce_hz": contact["bounce"].frequency_hz,
        "bounce_damping_ratio": contact["bounce"].damping_ratio,
        "tilt_hz": tilt,
        "roller_stiffness_n_per_m": [float(v) for v in ks],
    })
    return out


def paper_case_modes(
    bounce_hz: float = 745.0,
    tilt_hz: tuple[float, float] = (580.0, 582.0),
    damping_ratio: float = 0.018,
    *,
    rig: RigConfig | None = None,
    channels: Sequence[str] | None = None,
    hammer_xy_m: tuple[float, float] | None = None,
) -> list[SynthMode]:
    """The rig's mode shapes with the contact modes moved to chosen frequencies (the bench's reference case).

    Slightly uneven rollers fix the orientation of the tilt pair; the shapes are the rig model's.
    """
    rig = rig or load_rig()
    modes = rig_truth_modes(rig, [4.65e7, 4.65e7, 4.70e7], channels, hammer_xy_m=hammer_xy_m)
    out, tilts = [], iter(sorted(tilt_hz))
    for m in modes:
        if m.kind == "bounce":
            m = SynthMode("bounce", bounce_hz, damping_ratio, m.residue)
        elif m.kind == "tilt":
            m = SynthMode("tilt", next(tilts), damping_ratio, m.residue)
        out.append(m)
    return out
