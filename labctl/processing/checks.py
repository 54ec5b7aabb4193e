"""Single-impact checks run right after each blow: double hit, overload, pulse width, low force.

The force pulse is located on a baseline-removed, polarity-corrected force record. Its width is the
half-sine equivalent duration (1.5 × the full width at half maximum, exact for a half-sine). A second hit
is searched with a filter matched to the measured main pulse (zero-mean over three pulse lengths, so
baseline drift cancels and anti-alias filter ringing, far above the pulse's band, is strongly suppressed):
its output, scaled so the main pulse reads 1, is the second hit's amplitude ratio.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike

DOUBLE_HIT = "double_hit"
OVERLOAD = "overload"
PULSE_WIDTH = "pulse_width"
LOW_FORCE = "low_force"
LOW_COHERENCE = "low_coherence"
REASONS = (DOUBLE_HIT, OVERLOAD, PULSE_WIDTH, LOW_FORCE, LOW_COHERENCE)
PULSE_SEARCH_S = 5e-3  # the blow's extent is searched this far either side of its peak
PLATEAU_SEARCH_S = 0.2  # a clipped response's plateaus lie within this long after the blow
PLATEAU_FALSE_ALARM = 1e-4  # chance, per channel extreme, that a natural peak is taken for a clip
FURTHER_PULSE_SIGMAS = 4.5  # a matched-filter peak this far above the force noise is a further pulse whose
# force joins the force window (however small: its response is in the responses); ≥ double_hit_ratio rejects


@dataclass(frozen=True)
class CheckConfig:
    """Acceptance thresholds for one impact (and, for coherence, for the impact set)."""

    overload_fraction: float = 0.95  # of a channel's range
    pulse_width_min_s: float = 1.0e-4  # the hammer tip's pulse range
    pulse_width_max_s: float = 1.0e-3
    min_peak_force_n: float = 10.0
    double_hit_ratio: float = 0.05  # a second pulse at least this fraction of the first rejects the impact
    double_hit_noise_sigmas: float = 6.0  # ... provided it also stands this far above the force noise
    min_coherence: float = 0.9  # at the identified modes, over the impact set
    double_hit_window_s: float = 0.25  # matched-filter search this far around the blow (raw force beyond)

    def __post_init__(self) -> None:
        if not 0 < self.overload_fraction <= 1:
            raise ValueError(f"overload_fraction = {self.overload_fraction!r}: expected a fraction in (0, 1]")
        if not 0 < self.pulse_width_min_s < self.pulse_width_max_s:
            raise ValueError(f"pulse width range {self.pulse_width_min_s!r}..{self.pulse_width_max_s!r} s: "
                             "expected 0 < min < max")
        if not 0 < self.double_hit_ratio < 1:
            raise ValueError(f"double_hit_ratio = {self.double_hit_ratio!r}: expected a fraction in (0, 1)")
        if not 0 <= self.min_coherence <= 1:
            raise ValueError(f"min_coherence = {self.min_coherence!r}: expected a value in [0, 1]")


@dataclass(frozen=True)
class ImpactCheck:
    """Outcome of the checks on one impact; a rejected impact keeps its data and names its reasons."""

    index: int
    accepted: bool
    reasons: tuple[str, ...]
    peak_force_n: float
    pulse_width_s: float
    pulse_start: int = 0  # first sample of the blow
    pulse_end: int = 0  # last sample of the blow
    second_hit_ratio: float = 0.0  # largest other pulse / main pulse (matched filter)
    second_hit_delay_s: float | None = None  # its delay after the main pulse (negative: before it)
    overloaded: tuple[str, ...] = ()
    force_noise_n: float = 0.0
    polarity: float = 1.0  # -1 when the force channel reads blows as negative
    notes: tuple[str, ...] = field(default=())
    further_pulses: tuple[tuple[int, int], ...] = ()  # (first, last sample) of smaller second hits kept in the force

    def rejected_for(self, reason: str, note: str = "") -> ImpactCheck:
        """The same check with one more rejection reason."""
        reasons = self.reasons if reason in self.reasons else (*self.reasons, reason)
        return replace(self, accepted=False, reasons=reasons, notes=(*self.notes, note) if note else self.notes)


@dataclass(frozen=True)
class Pulse:
    """The located main blow on a baseline-free, positive force record."""

    force_n: np.ndarray
    peak: int
    start: int
    end: int
    peak_n: float
    width_s: float
    noise_n: float
    polarity: float


def _noise_sigma(x: np.ndarray) -> float:
    """Robust white-noise σ from first differences of the record's last part (the blow is early)."""
    d = np.diff(x[-min(len(x), 4096):])
    return float(1.4826 * np.median(np.abs(d)) / math.sqrt(2.0)) if len(d) else 0.0


def _crossing(x: np.ndarray, i0: int, i1: int, level: float) -> float:
    """Fractional index where x crosses ``level`` between samples i0 and i1 (linear interpolation)."""
    a, b = x[i0], x[i1]
    return i0 + (level - a) / (b - a) * (i1 - i0) if b != a else float(i0)


def locate_pulse(force_n: ArrayLike, fs_hz: float) -> Pulse:
    """Find the main blow: baseline, polarity, peak, extent and half-sine equivalent width."""
    f = np.asarray(force_n, dtype=float)
    base = float(np.median(f[:: max(1, len(f) // 8192)]))
    g = f - base
    polarity = -1.0 if -g.min() > g.max() else 1.0
    if polarity < 0:
        g = -g
    noise = _noise_sigma(g)
    peak = int(np.argmax(g))
    p = float(g[peak])
    lo = max(0.02 * p, 3.0 * noise)
    span = max(8, int(PULSE_SEARCH_S * fs_hz))
    i0 = max(0, peak - span)
    before, after = g[i0:peak], g[peak:peak + span]
    below_l = np.flatnonzero(before <= lo)
    below_r = np.flatnonzero(after <= lo)
    start = i0 + int(below_l[-1]) + 1 if len(below_l) else i0
    end = peak + int(below_r[0]) - 1 if len(below_r) else peak + len(after) - 1
    half = 0.5 * p
    left = np.flatnonzero(before < half)
    right = np.flatnonzero(after < half)
    t0 = _crossing(g, i0 + int(left[-1]), i0 + int(left[-1]) + 1, half) if len(left) else float(start)
    t1 = _crossing(g, peak + int(right[0]) - 1, peak + int(right[0]), half) if len(right) else float(end)
    width = 1.5 * max(float(t1 - t0), 0.0) / fs_hz
    return Pulse(g, peak, start, end, p, width, noise, polarity)


@dataclass(frozen=True)
class _Matched:
    """The matched filter's output around the blow (the main pulse's own neighbourhood masked)."""

    ratio: np.ndarray  # index j: the template at sample lo + j + n_t, scaled so the blow reads 1
    lo: int
    hi: int
    n_t: int
    j0: int
    main: float


def _matched(pulse: Pulse, fs_hz: float, window_s: float) -> _Matched | None:
    g = pulse.force_n
    tpl = g[pulse.start:pulse.end + 1]
    n_t = len(tpl)
    lo = max(0, pulse.start - n_t - int(window_s * fs_hz))
    hi = min(len(g), pulse.end + n_t + int(window_s * fs_hz))
    if n_t < 1 or hi - lo < 3 * n_t + 2:
        return None
    kernel = np.concatenate([np.zeros(n_t), tpl, np.zeros(n_t)])
    kernel -= kernel.mean()
    main = float(kernel @ kernel)
    if not main > 0:
        return None
    ratio = np.correlate(g[lo:hi], kernel, mode="valid") / main
    j0 = pulse.start - n_t - lo
    guard = n_t + max(2, n_t // 2)
    ratio[max(0, j0 - guard + 1):max(0, j0 + guard)] = -np.inf
    return _Matched(ratio, lo, hi, n_t, j0, main)


def second_hit(pulse: Pulse, fs_hz: float, window_s: float,
               matched: _Matched | None = None) -> tuple[float, float | None, float]:
    """Largest other pulse relative to the main one: (ratio, delay s, ratio the noise alone could reach).

    Within ``window_s`` of the blow the matched filter is used; beyond it (a rare, late second blow) the
    raw force is compared with the peak.
    """
    g = pulse.force_n
    m = matched if matched is not None else _matched(pulse, fs_hz, window_s)
    n_t = pulse.end + 1 - pulse.start
    lo = max(0, pulse.start - n_t - int(window_s * fs_hz))
    hi = min(len(g), pulse.end + n_t + int(window_s * fs_hz))
    best: tuple[float, float | None, float] = (0.0, None, pulse.noise_n / max(pulse.peak_n, 1e-300))
    if m is not None:
        k = int(np.argmax(m.ratio))
        if np.isfinite(m.ratio[k]):
            best = (float(m.ratio[k]), (k - m.j0) / fs_hz, pulse.noise_n / math.sqrt(m.main))
    outside = np.concatenate([g[:lo], g[hi:]])
    if len(outside) and pulse.peak_n > 0:
        k = int(np.argmax(outside))
        raw = float(outside[k]) / pulse.peak_n
        noise_raw = pulse.noise_n / pulse.peak_n
        if raw / max(noise_raw, 1e-300) > best[0] / max(best[2], 1e-300) and raw > best[0]:
            at = k if k < lo else k - lo + hi
            best = (raw, (at - pulse.start) / fs_hz, noise_raw)
    return best


def further_pulses(pulse: Pulse, fs_hz: float, window_s: float, sigmas: float = FURTHER_PULSE_SIGMAS,
                   matched: _Matched | None = None) -> tuple[tuple[int, int], ...]:
    """Every other pulse the matched filter sees above ``sigmas`` × its noise within ``window_s`` of the blow:
    (first, last sample) each, for the force window to keep."""
    from scipy.signal import find_peaks

    m = matched if matched is not None else _matched(pulse, fs_hz, window_s)
    if m is None:
        return ()
    level = sigmas * pulse.noise_n / math.sqrt(m.main)
    ratio = np.where(np.isfinite(m.ratio), m.ratio, 0.0)
    peaks, _ = find_peaks(ratio, height=level, distance=max(1, m.n_t))
    return tuple((m.lo + int(j) + m.n_t, m.lo + int(j) + 2 * m.n_t - 1) for j in peaks)


def _ranges(ranges: float | Sequence[float] | None, n: int) -> np.ndarray | None:
    if ranges is None:
        return None
    r = np.broadcast_to(np.asarray(ranges, dtype=float), (n,))
    return r


def _resolution(x: np.ndarray) -> float:
    """The data's step when they lie on an ADC's grid (the smallest change, every change a multiple of it);
    0 when they do not (floating-point data, resolved to their own precision)."""
    steps = np.abs(np.diff(x))
    steps = steps[steps > 0]
    if len(steps) == 0:
        return 0.0
    lsb = float(steps.min())
    ratio = steps / lsb
    on_grid = np.abs(ratio - np.round(ratio)) < 0.01
    return lsb if np.mean(on_grid) > 0.9 else 0.0


def _plateau_clipped(x: np.ndarray) -> bool:
    """Clipping without a known range: the record's extreme value reached more than once. An analogue peak
    repeats to the last digit only by chance: its top samples differ by up to the drop to their neighbours,
    so ``n`` equal hits at an extreme happen naturally with probability ~ (resolution / drop)^(n-1), the
    resolution being the ADC's step or, for floating-point data, single precision at the value. A repeat is
    a clip when that chance is below ``PLATEAU_FALSE_ALARM``. A flat (dead) channel, or one resting at its
    extreme, is not an overload."""
    top, bottom = x.max(), x.min()
    if top == bottom:
        return False
    quantum, baseline = -1.0, None
    for value, sign in ((top, 1.0), (bottom, -1.0)):
        at = np.flatnonzero(x == value)
        if len(at) < 2:
            continue
        if baseline is None:
            baseline = float(np.median(x))
        if value == baseline:  # a noise-free record resting at its extreme (a force exactly 0 between blows)
            continue
        if quantum < 0:
            quantum = _resolution(x[: min(len(x), 4096)])
        resolution = quantum if quantum > 0 else float(np.spacing(np.float32(abs(value))))
        neighbours = np.setdiff1d(np.concatenate([at - 1, at + 1]), at)
        neighbours = neighbours[(neighbours >= 0) & (neighbours < len(x))]
        if len(neighbours) == 0:
            continue
        drop = float(np.min(sign * (value - x[neighbours])))
        if drop > 0 and (resolution / drop) ** (len(at) - 1) < PLATEAU_FALSE_ALARM:
            return True
    return False


def overloaded_channels(
    force_n: np.ndarray,
    accel_m_per_s2: np.ndarray,
    *,
    accel_ranges: float | Sequence[float] | None,
    force_range_n: float | None,
    fraction: float,
    names: Sequence[str],
    extremes: tuple[np.ndarray, np.ndarray] | None = None,
    upto: int | None = None,
) -> tuple[str, ...]:
    """Channels that reached ``fraction`` of their range, or that show a clipped plateau when no range is
    known. ``extremes`` (per-channel max and min) spare a pass over the data when the caller has them."""
    out: list[str] = []
    ranges = _ranges(accel_ranges, accel_m_per_s2.shape[0])
    if ranges is not None:
        top, bottom = extremes if extremes is not None else (accel_m_per_s2.max(axis=-1), accel_m_per_s2.min(axis=-1))
        peaks = np.maximum(top, -bottom)
    # a response's extremes come right after the blow: the plateau search looks there (exact values compared)
    early = accel_m_per_s2[:, :upto] if upto else accel_m_per_s2
    top_all, bottom_all = early.max(axis=-1), early.min(axis=-1)
    repeats = (np.count_nonzero(early == top_all[:, None], axis=-1) > 1) | (
        np.count_nonzero(early == bottom_all[:, None], axis=-1) > 1)
    for c, name in enumerate(names):
        near_full_scale = ranges is not None and np.isfinite(ranges[c]) and peaks[c] >= fraction * ranges[c]
        # below a stated range an amplifier may clip first; an extreme reached once is no plateau
        if near_full_scale or repeats[c] and _plateau_clipped(early[c]):
            out.append(name)
    f_peak = float(np.max(np.abs(force_n)))
    if force_range_n is not None and f_peak >= fraction * force_range_n or _plateau_clipped(force_n):
        out.append("force")
    return tuple(out)


def check_impact(
    force_n: ArrayLike,
    accel_m_per_s2: ArrayLike,
    fs_hz: float,
    *,
    index: int = 0,
    accel_ranges: float | Sequence[float] | None = None,
    force_range_n: float | None = None,
    config: CheckConfig = CheckConfig(),  # noqa: B008 - frozen, shared default is safe
    channels: Sequence[str] | None = None,
    extremes: tuple[np.ndarray, np.ndarray] | None = None,
) -> ImpactCheck:
    """Check one impact: ``double_hit``, ``overload``, ``pulse_width``, ``low_force`` (each a named reason).

    ``accel_ranges`` (one value or one per channel, m/s²) and ``force_range_n`` are the channels' full
    scales; without them an overload is recognised by a clipped plateau. ``extremes`` are the response
    channels' (max, min) when the caller already has them.
    """
    f = np.asarray(force_n, dtype=float)
    a = np.asarray(accel_m_per_s2, dtype=float)
    if a.ndim == 1:
        a = a[None, :]
    if f.ndim != 1 or a.shape[-1] != f.shape[0]:
        raise ValueError(f"impact {index}: force has shape {f.shape} and accel {a.shape}; expected (n,) and (n_ch, n)")
    names = tuple(channels) if channels is not None else tuple(f"channel {c}" for c in range(a.shape[0]))
    pulse = locate_pulse(f, fs_hz)
    reasons: list[str] = []
    notes: list[str] = []
    matched = _matched(pulse, fs_hz, config.double_hit_window_s)
    ratio, delay, noise_ratio = second_hit(pulse, fs_hz, config.double_hit_window_s, matched)
    threshold = max(config.double_hit_ratio, config.double_hit_noise_sigmas * noise_ratio)
    if ratio >= threshold:
        reasons.append(DOUBLE_HIT)
        notes.append(f"second pulse {ratio:.0%} of the first at {1e3 * (delay or 0.0):+.1f} ms")
    extra = further_pulses(pulse, fs_hz, config.double_hit_window_s, matched=matched)
    if extra and ratio < threshold:
        at = ", ".join(f"{1e3 * (a - pulse.start) / fs_hz:+.1f}" for a, _ in extra[:5])
        notes.append(f"smaller pulse(s) at {at} ms (largest {ratio:.1%} of the blow) kept in the force window")
    upto = None
    if len(f) > 4 * int(PLATEAU_SEARCH_S * fs_hz):
        upto = pulse.end + int(PLATEAU_SEARCH_S * fs_hz)
    over = overloaded_channels(f, a, accel_ranges=accel_ranges, force_range_n=force_range_n,
                               fraction=config.overload_fraction, names=names, extremes=extremes, upto=upto)
    if over:
        reasons.append(OVERLOAD)
        notes.append(f"near full scale: {', '.join(over)}")
    if not config.pulse_width_min_s <= pulse.width_s <= config.pulse_width_max_s:
        reasons.append(PULSE_WIDTH)
        notes.append(f"pulse {1e3 * pulse.width_s:.2f} ms outside {1e3 * config.pulse_width_min_s:.2f}-"
                     f"{1e3 * config.pulse_width_max_s:.2f} ms")
    if pulse.peak_n < config.min_peak_force_n or pulse.peak_n < 20.0 * pulse.noise_n:
        reasons.append(LOW_FORCE)
        notes.append(f"peak {pulse.peak_n:.3g} N below {config.min_peak_force_n:g} N or the noise")
    return ImpactCheck(
        index=index,
        accepted=not reasons,
        reasons=tuple(reasons),
        peak_force_n=pulse.peak_n,
        pulse_width_s=pulse.width_s,
        pulse_start=pulse.start,
        pulse_end=pulse.end,
        second_hit_ratio=max(ratio, 0.0),
        second_hit_delay_s=delay,
        overloaded=over,
        force_noise_n=pulse.noise_n,
        polarity=pulse.polarity,
        notes=tuple(notes),
        further_pulses=extra,
    )
