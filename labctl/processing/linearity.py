"""Linearity across a step's impacts: does the bounce frequency move with the blow's peak force?

The contact is nonlinear (Hertz, Tripp): a blow large against the preload stiffens or softens the
contact during the ring-down, and the bounce frequency then depends on the hammer level. Each impact's own
bounce frequency is estimated to first order from the step's fit (its single-impact FRF mapped through the
fit's linearised variable projection), with its own uncertainty (response noise for its share of the force
energy, its own force noise). A weighted straight line against the peak force gives the slope; the slope's
z value decides at a stated level whether the frequency depends on the hammer level.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.special import chdtrc, ndtri

from labctl.processing.force_noise import ForceNoiseWidener, force_noise_on
from labctl.processing.frf import Spectra
from labctl.processing.modes import impact_shifts
from labctl.processing.search import ContactModes, channel_weights

LINEARITY_LEVEL = 0.001  # two-sided level of the "frequency depends on the peak force" test
# The a² backbone is the first-order term, and a blow's modal amplitude also depends on where the hammer lands:
# this share of the removed shift is kept as its uncertainty.
MODEL_SHARE = 0.25


@dataclass(frozen=True)
class Linearity:
    """Bounce frequency per impact against its peak force, the fitted slope and the test's verdict."""

    peak_force_n: tuple[float, ...]
    bounce_hz: tuple[float, ...]
    bounce_hz_std: tuple[float, ...]
    slope_hz_per_n: float
    slope_std_hz_per_n: float
    z: float
    level: float
    nonlinear: bool

    def to_dict(self) -> dict:
        return {"peak_force_n": list(self.peak_force_n), "bounce_hz": list(self.bounce_hz),
                "bounce_hz_std": list(self.bounce_hz_std), "slope_hz_per_n": self.slope_hz_per_n,
                "slope_std_hz_per_n": self.slope_std_hz_per_n, "z": self.z, "level": self.level,
                "nonlinear": self.nonlinear}

    def warning(self) -> str | None:
        if not self.nonlinear:
            return None
        lo, hi = min(self.peak_force_n), max(self.peak_force_n)
        return (f"the bounce frequency moves with the blow: {100 * self.slope_hz_per_n:+.3f} Hz per 100 N of peak "
                f"force over {lo:.0f}-{hi:.0f} N (z {self.z:+.1f}, test at level {self.level:g}): the contact "
                "is not linear at this hammer level — the hammer level is too high for the preload, hit softer")


def linearity_check(peak_force_n: Sequence[float], bounce_hz: Sequence[float], bounce_hz_std: Sequence[float],
                    level: float = LINEARITY_LEVEL) -> Linearity | None:
    """Weighted straight line of the impacts' bounce frequencies against their peak forces (None: fewer than
    two impacts or all blows of one size)."""
    p, f, s = (np.asarray(v, float) for v in (peak_force_n, bounce_hz, bounce_hz_std))
    line = _weighted_line(p, f, s)
    if line is None:
        return None
    z = line.slope / line.slope_std
    return Linearity(tuple(map(float, p)), tuple(map(float, f)), tuple(map(float, s)), line.slope, line.slope_std, z,
                     level, bool(abs(z) > -ndtri(level / 2)))


@dataclass(frozen=True)
class _Line:
    """A weighted straight line: slope, its 1-σ, the weighted mean of f and the misfit's p value (1 when no
    degree of freedom is left to judge it)."""

    slope: float
    slope_std: float
    mean: float
    fit_p: float


def _weighted_line(x: np.ndarray, f: np.ndarray, s: np.ndarray) -> _Line | None:
    """f against x weighted by 1/s² (None: fewer than two points, a non-finite or non-positive σ, or x of one
    value)."""
    if len(x) < 2 or not (np.all(np.isfinite(s)) and np.all(s > 0) and np.all(np.isfinite(x))):
        return None
    if float(np.ptp(x)) < 1e-3 * float(np.max(np.abs(x))):
        return None
    w = 1.0 / s**2
    xm = float(np.sum(w * x) / np.sum(w))
    sxx = float(np.sum(w * (x - xm) ** 2))
    if not sxx > 0:
        return None
    fm = float(np.sum(w * f) / np.sum(w))
    slope = float(np.sum(w * (x - xm) * (f - fm)) / sxx)
    misfit = float(np.sum(w * (f - fm - slope * (x - xm)) ** 2))
    fit_p = float(chdtrc(len(x) - 2, misfit)) if len(x) > 2 else 1.0
    return _Line(slope, 1.0 / math.sqrt(sxx), fm, fit_p)


@dataclass(frozen=True)
class ZeroAmplitude:
    """The contact modes' shift from the blows' size: f_i = f0 + c·a_i² over the impacts (a_i the force
    spectrum at the bounce), so the step's H1-weighted frequency sits ``shift_hz`` above the small-blow limit."""

    c_hz_per_n2_s2: float  # c, the backbone curve's curvature in the blow's force spectrum at the bounce
    c_std_hz_per_n2_s2: float
    a2_eff_n2_s2: float  # the H1 weighting's effective a² (Σa⁴/Σa²)
    shift_hz: float  # step frequency minus its small-blow limit
    shift_std_hz: float
    z: float  # c over its 1-σ
    level: float
    significant: bool  # the blows' size moves the modes at the stated level

    def to_dict(self) -> dict:
        return {"c_hz_per_n2_s2": self.c_hz_per_n2_s2, "c_std_hz_per_n2_s2": self.c_std_hz_per_n2_s2,
                "a2_eff_n2_s2": self.a2_eff_n2_s2, "shift_hz": self.shift_hz, "shift_std_hz": self.shift_std_hz,
                "z": self.z, "level": self.level, "significant": self.significant}


def zero_amplitude(amplitude_n_s: Sequence[float], bounce_hz: Sequence[float], bounce_hz_std: Sequence[float],
                   half_bandwidth_hz: float = math.inf, level: float = LINEARITY_LEVEL) -> ZeroAmplitude | None:
    """How far the blows' size moved a step's bounce above its small-blow limit (None: fewer than two impacts
    or blows of one size).

    A smooth contact nonlinearity moves a mode's frequency with the square of its amplitude (the backbone
    curve ω(A) = ω0 + κA² + O(A⁴)), and a blow's modal amplitude is proportional to its force spectrum a_i at the
    mode. The H1 average weights impact i by a_i², so the step's frequency is f0 + c·Σa⁴/Σa²: that term is the
    shift, with the uncertainty of c, the bound (f_i - f̄)²/Γ of the impacts' first-order frequencies (Γ the half-
    power half-bandwidth) and a share of the shift for higher-order terms and where each blow landed. The
    shift is an estimate to carry, not to remove: an extrapolation over blows of similar size multiplies their
    scatter, and the blow moves the tilt modes by other amounts than the bounce. When the impacts contradict the
    a² line (lack of fit at ``LINEARITY_LEVEL``: e.g. blows that nearly open the contact saturate it), the
    extrapolation's shape is unknown: its model share becomes the larger of the shift and the difference to a
    backbone in a itself.
    """
    a, f, s = (np.asarray(v, float) for v in (amplitude_n_s, bounce_hz, bounce_hz_std))
    x = a**2
    line = _weighted_line(x, f, s)
    if line is None:
        return None
    c, c_std, fm = line.slope, line.slope_std, line.mean
    a2_eff = float(np.sum(x**2) / np.sum(x))
    linearisation = float(np.max((f - fm) ** 2)) / half_bandwidth_hz
    z = c / c_std
    shift = c * a2_eff
    model = MODEL_SHARE * abs(shift)
    if line.fit_p < LINEARITY_LEVEL:
        # the blows do not follow the a² backbone (a contact near opening saturates it): the small-blow limit's
        # shape is unknown between that and a backbone in a itself, whose extrapolation is steeper
        steep = _weighted_line(a, f, s)
        if steep is not None:
            a_eff = float(np.sum(x * a) / np.sum(x))
            model = max(abs(shift), abs(steep.slope * a_eff - shift))
    return ZeroAmplitude(c, c_std, a2_eff, shift, math.sqrt((c_std * a2_eff) ** 2 + linearisation**2 + model**2), z,
                         level, bool(abs(z) > -ndtri(level / 2)))


# The impacts' first-order frequencies carry approximate stds: the blows' shift is carried only on strong evidence.
SMALL_BLOW_LEVEL = 1e-6


def small_blow_limit(modes: ContactModes, spectra: Spectra, used: list[int], lin: Linearity | None,
                      fs_hz: float) -> ZeroAmplitude | None:
    """How far the blows' size moved the step's bounce above its small-blow limit (None: not estimable)."""
    if lin is None:
        return None
    b = modes.classes.bounce
    f_b = float(modes.fit.frequencies_hz[b])
    k = int(np.argmin(np.abs(spectra.frequencies_hz - f_b)))
    amplitude = np.abs(spectra.force[used, k]) / fs_hz  # the blow's spectral density at the bounce, N·s
    return zero_amplitude(amplitude, lin.bounce_hz, lin.bounce_hz_std, float(modes.fit.damping_ratios[b]) * f_b,
                          level=SMALL_BLOW_LEVEL)


def widened(modes: ContactModes, small: ZeroAmplitude) -> ContactModes:
    """The contact modes with the blows' shift (relative to the bounce, as the blow changes every roller's
    stiffness) and its uncertainty added to each frequency's 1-σ; the frequencies themselves are left as fitted."""
    fit = modes.fit
    f_b = float(fit.frequencies_hz[modes.classes.bounce])
    rel_std = math.hypot(small.shift_hz, small.shift_std_hz) / f_b
    stds = np.hypot(fit.frequency_std_hz, fit.frequencies_hz * rel_std)
    return replace(modes, fit=replace(fit, frequency_std_hz=stds))


def step_linearity(modes: ContactModes, spectra: Spectra, used: list[int], peaks: list[float], sigma_f: np.ndarray,
                   live: np.ndarray, noise: np.ndarray, widen: ForceNoiseWidener | None = None) -> Linearity | None:
    """Each used impact's bounce frequency (first order from the step's fit) against its peak force."""
    if len(used) < 2 or not spectra.force_windows:
        return None
    fit, band, b = modes.fit, modes.band, modes.classes.bounce
    f_band = spectra.force[:, band][used].astype(complex)
    x_band = spectra.response[:, :, band][used][:, live]
    with np.errstate(divide="ignore", invalid="ignore"):
        h_each = x_band / f_band[:, None, :]
    if not np.all(np.isfinite(h_each)):
        return None
    h_step = np.sum(x_band * f_band.conj()[:, None, :], axis=0) / np.sum(np.abs(f_band) ** 2, axis=0)
    lin = widen.linearised(fit, band) if widen is not None else None
    fn = widen.force_noise(band) if widen is not None else force_noise_on(spectra, used, sigma_f, band)
    try:
        shifts, stds = impact_shifts(fit, spectra.frequencies_hz[band], h_step, h_each, fn,
                                     decay_rate_per_s=spectra.decay_rate_per_s,
                                     channel_weights=channel_weights(noise[live]),
                                     noise_inflation=spectra.noise_inflation / (band.step or 1), linearised=lin)
    except np.linalg.LinAlgError:
        return None
    f_b = float(fit.frequencies_hz[b])
    return linearity_check(peaks, f_b + shifts[:, 2 * b], stds[:, 2 * b])
