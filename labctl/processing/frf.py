"""Windowed spectra of an impact set and the FRF estimates H1, H2 and coherence averaged over impacts.

Windows: the force keeps only the blow — the pulse and whatever stands above the force channel's noise right
around it (anti-alias filter ringing), with short cosine tapers — because every noise sample left in the
window perturbs the force spectrum the FRF is divided by; force and responses are both
multiplied by the same exponential window ``exp(-a·t)``. Multiplying both by ``exp(-a·t)`` turns the
measured FRF into ``H(s)`` evaluated at ``s = iω + a``: every pole appears shifted by ``-a`` (the window's
"added damping"), which the mode fit undoes exactly by evaluating its model at ``iω + a``.
Spectra are computed in single precision (the FFT's round-off stays > 100 dB below the signal).

The spectra span only the part of the record that holds the response: the records are cut at twice the time
the responses' ring-down takes to sink into each channel's noise (the start of the first run of blocks in
which no channel's energy of sample-to-sample differences — a high-pass that leaves out the slow support
modes and offsets — stands out of the level of the record's last blocks, at a false-alarm rate of 1e-3 over
the record), at least ``MIN_SPAN_S``. Past that point a record holds noise only: it would add to every line
of the spectra and nothing to the modes, while the shorter transform and the fewer lines cost a fraction of
the work. The exponential window keeps its rate (its end value at the record's end), so the window adds the
same small damping whatever the span.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft
from scipy.special import chdtri

from labctl.errors import InputError
from labctl.processing.checks import CheckConfig, check_impact

WORKERS = 2
_WORK = threading.local()
DECAY_BLOCK = 512  # samples per block of the ring-down scan (25 ms at 20 480 Hz) ...
DECAY_STRIDE = 4  # ... of which every so-many sample pairs are differenced (independent noise terms)
DECAY_FALSE_ALARM = 1e-3  # chance that noise alone lengthens the analysed span, over the whole record
NOISE_BLOCKS = 16  # the record's last blocks give each channel's noise level
QUIET_BLOCKS = 3  # the ring-down ends where this many blocks in a row hold noise only ...
SCAN_BLOCKS = 8  # ... scanned from the start this many blocks at a time
MIN_SPAN_S = 0.2  # the analysed span's least length (5 Hz lines): a few lines across any contact mode


@dataclass(frozen=True)
class WindowConfig:
    """Exponential window end value (None: no window) and the force window's extent around the blow."""

    exponential_end: float | None = 0.01  # the window's value at the end of the record
    trim_to_decay: bool = True  # analyse up to twice the responses' ring-down (False: the whole record)
    force_pre_s: float = 0.5e-3  # the force window reaches at most this far before the pulse ...
    force_post_s: float = 2.0e-3  # ... and after it, where the force still stands above its noise (ringing)
    force_noise_sigmas: float = 4.0
    taper_s: float = 0.1e-3
    max_frequency_hz: float | None = 3000.0  # spectra kept up to here (None: Nyquist): the rig's contact modes
    # cannot exceed what K_setup alone allows (~2.5 kHz on the paper's rig) and its first flexible mode is 2.3 kHz

    def decay_rate_per_s(self, n_samples: int, fs_hz: float) -> float:
        """The exponential window's rate a (1/s): exp(-a·t) falls to ``exponential_end`` over the record."""
        if self.exponential_end is None:
            return 0.0
        if not 0 < self.exponential_end <= 1:
            raise ValueError(f"exponential window end value {self.exponential_end!r}: expected a value in (0, 1]")
        return -math.log(self.exponential_end) * fs_hz / max(n_samples - 1, 1)


@dataclass(frozen=True)
class Spectra:
    """Per-impact windowed spectra on ``frequencies_hz``: force (n_imp, n_f), response (n_imp, n_ch, n_f)."""

    frequencies_hz: np.ndarray
    force: np.ndarray
    response: np.ndarray
    decay_rate_per_s: float
    noise_inflation: float  # variance factor for fitted parameters from the window's bin-to-bin correlation
    force_windows: tuple[tuple[np.ndarray, np.ndarray], ...] = ()  # per impact: (sample indices, force window
    # × exponential window) — where the force channel's noise enters the force spectrum
    n_samples: int = 0

    @property
    def fit_line_step(self) -> int:
        """Every how many lines a fit needs: the exponential window correlates the noise of neighbouring lines
        over about ``noise_inflation`` of them, so a third of that keeps the information of every line (the
        bounce's error grows by ≤ 3 % on the bench) at a third of the work."""
        return max(1, round(self.noise_inflation / 3))


@dataclass(frozen=True)
class FrfEstimate:
    """H1, H2 (n_ch, n_f) and ordinary coherence averaged over the used impacts."""

    frequencies_hz: np.ndarray
    h1: np.ndarray
    h2: np.ndarray
    coherence: np.ndarray
    used: tuple[int, ...]
    response_power: np.ndarray  # (n_ch,) Σ|X|² over impacts and lines: 0 for a flat (dead) channel


def force_window(force_n: np.ndarray, fs_hz: float, start: int, end: int, noise_n: float,
                 cfg: WindowConfig, segments: tuple[tuple[int, int], ...] = ()) -> tuple[int, np.ndarray]:
    """The force window's support: (first sample, values) — 1 over the pulse and the samples around it that
    stand above ``force_noise_sigmas`` × the noise (within pre/post), cosine tapers outside. ``segments``
    (first, last sample) are further pulses (second hits): each is kept the same way, so their force is
    in the force spectrum as their response is in the responses; the noise between them is left out."""
    lo, w = _one_window(force_n, fs_hz, start, end, noise_n, cfg)
    for a, b in segments:
        lo2, w2 = _one_window(force_n, fs_hz, a, b, noise_n, cfg)
        new_lo, new_hi = min(lo, lo2), max(lo + len(w), lo2 + len(w2))
        merged = np.zeros(new_hi - new_lo)
        merged[lo - new_lo:lo - new_lo + len(w)] = w
        part = merged[lo2 - new_lo:lo2 - new_lo + len(w2)]
        np.maximum(part, w2, out=part)
        lo, w = new_lo, merged
    return lo, w


def _one_window(force_n: np.ndarray, fs_hz: float, start: int, end: int, noise_n: float,
                cfg: WindowConfig) -> tuple[int, np.ndarray]:
    n = len(force_n)
    start, end = max(0, min(start, n - 1)), max(0, min(end, n - 1))
    taper = max(1, int(round(cfg.taper_s * fs_hz)))
    level = cfg.force_noise_sigmas * noise_n
    lo_max = max(0, start - int(round(cfg.force_pre_s * fs_hz)))
    hi_max = min(n, end + 1 + int(round(cfg.force_post_s * fs_hz)))
    above_pre = np.flatnonzero(np.abs(force_n[lo_max:start]) > level)
    above_post = np.flatnonzero(np.abs(force_n[end + 1:hi_max]) > level)
    a = lo_max + int(above_pre[0]) if len(above_pre) else start
    b = end + 2 + int(above_post[-1]) if len(above_post) else end + 1
    a, b = max(0, a - 1), min(n, b + 1)
    lo, hi = max(0, a - taper), min(n, b + taper)
    ramp = 0.5 - 0.5 * np.cos(np.pi * (np.arange(taper) + 0.5) / taper)
    w = np.ones(hi - lo)
    w[: a - lo] = ramp[taper - (a - lo):]
    w[b - lo:] = ramp[::-1][: hi - b]
    return lo, w


def ring_down_samples(responses: np.ndarray) -> int:
    """Samples from the record's start to the first of ``QUIET_BLOCKS`` blocks in a row in which no response
    stands out of its channel's noise (the record's length if none). ``responses`` is (n_impacts, n_channels,
    n); the noise is the record's last ``NOISE_BLOCKS`` blocks; the scan uses differences of neighbouring
    samples, so slow support modes and sensor offsets do not keep it going."""
    n = responses.shape[-1]
    n_blocks = n // DECAY_BLOCK
    if n_blocks < NOISE_BLOCKS + QUIET_BLOCKS + 1:
        return n
    dof = DECAY_BLOCK // DECAY_STRIDE

    def energy(first: int, last: int) -> np.ndarray:
        a, b = first * DECAY_BLOCK, last * DECAY_BLOCK
        d = responses[..., a + 1:b:DECAY_STRIDE] - responses[..., a:b:DECAY_STRIDE]
        d = d.reshape(*responses.shape[:-1], last - first, dof)
        return np.einsum("...k,...k->...", d, d, dtype=np.float64)

    floor = energy(n_blocks - NOISE_BLOCKS, n_blocks).mean(axis=-1, keepdims=True)
    limit = floor * float(chdtri(dof, DECAY_FALSE_ALARM / (floor.size * n_blocks))) / dof
    first, stop = 0, n_blocks - NOISE_BLOCKS
    while True:
        last = min(first + SCAN_BLOCKS, stop)
        loud = (energy(first, last) > limit).reshape(-1, last - first).any(axis=0)
        run = 0
        for j, is_loud in enumerate(loud):
            run = 0 if is_loud else run + 1
            if run == QUIET_BLOCKS:
                return (first + j + 1 - QUIET_BLOCKS) * DECAY_BLOCK
        if last == stop:
            return n
        first = last - run  # a quiet run cut by the chunk's end is scanned again


def analysed_samples(responses: np.ndarray, fs_hz: float, least: int = 0) -> int:
    """The analysed span: twice the responses' ring-down, at least ``MIN_SPAN_S`` and ``least`` samples, at
    most the record, rounded up to a fast transform length."""
    n = responses.shape[-1]
    want = max(2 * ring_down_samples(responses), int(math.ceil(MIN_SPAN_S * fs_hz)), least)
    return min(n, sfft.next_fast_len(want, real=True))


def response_buffer(accel_m_per_s2: np.ndarray, n: int | None = None) -> np.ndarray:
    """Single-precision work array (n_impacts, 1 + n_channels, n) of the records' first ``n`` samples (default
    all): row 0 for the force, then the responses.

    ``impact_spectra`` windows and transforms it in place; made once, it also gives the channels' extremes over
    the samples analysed. The array is the calling thread's scratch space: the next call overwrites it.
    """
    n_imp, n_ch, n_all = accel_m_per_s2.shape
    n = n_all if n is None else min(n, n_all)
    shape = (n_imp, n_ch + 1, n)
    buf = getattr(_WORK, "buffer", None)
    if buf is None or buf.shape != shape:  # one per thread, reused: a fresh 10 MB array costs page faults
        buf = _WORK.buffer = np.empty(shape, dtype=np.float32)
    buf[:, 0] = 0.0
    np.copyto(buf[:, 1:], accel_m_per_s2[..., :n], casting="same_kind")
    return buf


def impact_spectra(
    force_n: np.ndarray,
    accel_m_per_s2: np.ndarray,
    fs_hz: float,
    pulses: list[tuple[int, int, float]],
    cfg: WindowConfig = WindowConfig(),  # noqa: B008 - frozen
    use: list[int] | None = None,
    buffer: np.ndarray | None = None,
    segments: list[tuple[tuple[int, int], ...]] | None = None,
) -> Spectra:
    """Window and transform the impacts ``use`` (default all); ``pulses`` holds (first sample, last sample,
    force noise N) of each of them, ``segments`` their further pulses (second hits) kept in the force
    window. Sensor offsets (the record before each blow) are removed. A ``response_buffer`` of the same
    data may be passed (its length is the span analysed, unless the blows reach beyond it): it is overwritten."""
    everything = list(range(accel_m_per_s2.shape[0]))
    use = everything if use is None else list(use)
    n = accel_m_per_s2.shape[2]
    rate = cfg.decay_rate_per_s(n, fs_hz)
    ends = [end for _, end, _ in pulses] + [b for extra in (segments or []) for _, b in extra]
    blow = min(n, max(ends, default=0) + int(math.ceil((cfg.force_post_s + 2 * cfg.taper_s) * fs_hz)) + 2)
    if buffer is not None and buffer.shape[-1] >= blow:  # the caller's span (see ``analysed_samples``)
        n = buffer.shape[-1]
        buf = buffer if use == everything else buffer[use]
    else:
        n = analysed_samples(accel_m_per_s2, fs_hz, least=blow) if cfg.trim_to_decay else n
        buf = response_buffer(accel_m_per_s2 if use == everything else accel_m_per_s2[use, :, :n], n)
    expw = np.exp(-rate * np.arange(n) / fs_hz)
    n_f = n // 2 + 1
    if cfg.max_frequency_hz is not None:
        n_f = min(n_f, int(math.floor(cfg.max_frequency_hz * n / fs_hz)) + 1)
    expw32 = expw.astype(np.float32)
    buf[:, 1:] *= expw32
    windows = []
    for i, (j, (start, end, noise)) in enumerate(zip(use, pulses, strict=True)):
        if start >= 16:
            pre = accel_m_per_s2[j, :, :start]
            offset = pre.mean(axis=-1)
            significant = np.abs(offset) > 4.0 * pre.std(axis=-1) / math.sqrt(start)
            for c in np.flatnonzero(significant):
                buf[i, 1 + c] -= np.float32(offset[c]) * expw32
        f_off = float(np.median(force_n[j, :start])) if start >= 16 else 0.0
        extra = segments[i] if segments is not None else ()
        lo, w = force_window(force_n[j, :n] - f_off, fs_hz, start, end, noise, cfg, extra)
        buf[i, 0, lo:lo + len(w)] = (force_n[j, lo:lo + len(w)] - f_off) * expw[lo:lo + len(w)] * w
        keep = np.flatnonzero(w > 0)
        windows.append((lo + keep, w[keep] * expw[lo + keep]))
    spec = sfft.rfft(buf, axis=-1, workers=WORKERS, overwrite_x=True)[..., :n_f]
    big_f = spec[:, 0]
    big_x = spec[:, 1:]
    freqs = np.arange(n_f) * fs_hz / n
    w_at_blow = float(np.mean([expw[min(max(s, 0), n - 1)] for s, _, _ in pulses])) if pulses else 1.0
    inflation = n * w_at_blow**2 / float(np.sum(expw**2))
    return Spectra(freqs, big_f, big_x, rate, inflation, tuple(windows), n)


def estimate_frf(spectra: Spectra, used: tuple[int, ...] | list[int]) -> FrfEstimate:
    """H1 = Σ X F* / Σ |F|², H2 = Σ |X|² / Σ F X*, coherence = |Σ X F*|² / (Σ|F|² Σ|X|²) over ``used``."""
    idx = list(used)
    if not idx:
        raise ValueError("no impact to average")
    sff = np.zeros(spectra.force.shape[-1], dtype=np.float32)
    sxf = np.zeros(spectra.response.shape[1:], dtype=np.complex64)
    sxx = np.zeros(spectra.response.shape[1:], dtype=np.float32)
    for i in idx:
        f, x = spectra.force[i], spectra.response[i]
        sff += np.abs(f) ** 2
        sxf += x * f.conj()
        sxx += np.abs(x) ** 2
    cross = np.abs(sxf) ** 2
    with np.errstate(all="ignore"):  # lines without signal (a dead channel) give 0, not NaN
        inv_ff = np.where(sff > 0, 1.0 / sff, 0.0).astype(np.float32)
        ratio = np.where(cross > 0, sxx / cross, 0.0).astype(np.float32)
        coh = np.where(sxx > 0, cross * inv_ff / sxx, 0.0).astype(np.float32)
    h1 = sxf * inv_ff
    h2 = sxf * ratio  # Σ|X|² / (Σ F X*) = Σ X F* · Σ|X|² / |Σ X F*|²
    power = sxx[:, 1:].sum(axis=1, dtype=np.float64)
    if not (np.isfinite(power).all() and np.isfinite(sff).all()):
        raise InputError("force or accel holds non-finite values (NaN or infinity)")
    return FrfEstimate(spectra.frequencies_hz, h1, h2, np.minimum(coh, 1.0, out=coh), tuple(idx), power)


def coherence_at(spectra: Spectra, used: list[int] | tuple[int, ...], bins: np.ndarray, weights: np.ndarray) -> float:
    """Coherence over ``used`` at the given bins, averaged over channels weighted by ``weights`` (n_ch, n_bins)."""
    idx = list(used)
    f = spectra.force[idx][:, bins]
    x = spectra.response[idx][:, :, bins]
    sff = np.sum(np.abs(f) ** 2, axis=0)
    sxf = np.sum(x * f.conj()[:, None, :], axis=0)
    sxx = np.sum(np.abs(x) ** 2, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        coh = np.where(sxx > 0, np.abs(sxf) ** 2 / (sff * sxx), 0.0)
    total = float(np.sum(weights))
    return float(np.sum(coh * weights) / total) if total > 0 else 0.0


def blow_spectra(force_n: np.ndarray, accel_m_per_s2: np.ndarray, fs_hz: float,
                 checks: CheckConfig | None = None, cfg: WindowConfig = WindowConfig()) -> Spectra:  # noqa: B008
    """Spectra of raw blows (n_impacts, n) / (n_impacts, n_ch, n), each windowed as ``identify`` windows it:
    its pulse and smaller further pulses located by the impact checks. For an FRF of blows before their step
    is identified (the per-hit gate); ``estimate_frf`` averages them."""
    force = np.atleast_2d(np.asarray(force_n, dtype=float))
    accel = np.asarray(accel_m_per_s2, dtype=float)
    if accel.ndim == 2:
        accel = accel[None]
    if accel.ndim != 3 or accel.shape[0] != force.shape[0] or accel.shape[2] != force.shape[1]:
        raise InputError(f"force has shape {force.shape} and accel {accel.shape}; expected (n_impacts, n_samples) "
                         "and (n_impacts, n_channels, n_samples)")
    found = [check_impact(force[i], accel[i], fs_hz, index=i, config=checks or CheckConfig())
             for i in range(force.shape[0])]
    pulses = [(c.pulse_start, c.pulse_end, c.force_noise_n) for c in found]
    return impact_spectra(force, accel, fs_hz, pulses, cfg, segments=[c.further_pulses for c in found])
