"""Find and fit the contact modes (bounce + tilt pair) in an FRF: band, start poles, fit, pair test.

The contact modes are sought between the rig's support modes and its first flexible mode (both from the
rig file). The fit band spans the dominant resonances there plus a few half-power bandwidths; the
multi-channel LSCF estimate gives three start poles that the variable-projection fit refines. If that fit
is not clearly resolved (a pole poorly determined, implausibly damped, too weak to matter or not worth
its parameters, or the two tilt poles within their uncertainty), a two-mode fit is made and the pair is
restarted from a few splits around its tilt; the best three-mode fit is kept only when a likelihood-ratio
test at level 0.001 prefers it and its tilt poles are apart beyond their uncertainty (force noise
included), otherwise the pair is reported as degenerate with the split it could hide. A fitted mode whose shape is
neither bounce nor tilt (a rail, mount or support resonance in the range) is never taken for a tilt: the range
is cut short of it and the fit repeated, or, when it lies among the contact modes, the pair is left unresolved.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.signal import find_peaks
from scipy.special import chdtri, ndtri

from labctl.physics import RigConfig
from labctl.processing.errors import ProcessingError
from labctl.processing.modes import ModalFit, fit_modes, lscf_poles, pole_to_mode
from labctl.processing.shapes import Classification, PredictedShapes, classify

N_CONTACT_MODES = 3
MAX_DAMPING = 0.3
MIN_RELATIVE_STRENGTH = 0.01  # a fitted "mode" with a smaller peak response is taken for model residue
PLAUSIBLE_DAMPING = 5.0  # contact modes damp alike: a pole damped far beyond (or below) the rig's ratio is residue
SHARPNESS = 0.1  # a real mode's frequency is known to better than this share of its half-power width
SPLITS = (0.05, 0.15, 0.4)  # tilt-pair start separations, in half-power widths of the single tilt
FIRST_FIT_ITER = 4  # a three-mode fit from the LSCF poles still moving after this many steps sits in a
# degenerate valley (a pole turning into residue): the two-mode fit and the split starts take over
TRIAL_ITER = 4  # the split starts are only ranked by their cost: the best one is refined to convergence
RESOLUTION_LEVEL = 0.001  # level of the one-pole-or-two test on the tilt pair (and of each mode's presence)
STRAY_SHARE = 0.5  # a non-bounce mode with less of its shape in the tilt subspace (and as little bounce) is no
# contact mode: a rail, mount or support resonance inside the range (rollers at ±50 % still give tilts ≥ 0.77)
STRAY_GAP_WIDTHS = 4.0  # a stray mode is cut out of the range only this many half-power widths from the rest
MAX_STRAY_CUTS = 2  # a further stray mode leaves the pair unresolved
Widen = Callable[[ModalFit], ModalFit]  # adds what the residuals cannot show (the force noise) to a fit's stds


@dataclass(frozen=True)
class ContactModes:
    """The fitted contact modes, which one is the bounce, and whether the tilt pair was resolved."""

    fit: ModalFit
    classes: Classification
    pair_resolved: bool
    band: slice
    split_std_hz: float | None = None  # unresolved pair: 1-σ of the split a three-mode fit gave (what could hide)
    stray_hz: tuple[float, ...] = ()  # modes in the range whose shape is neither bounce nor tilt (left out)


def search_range_hz(rig: RigConfig, pred: PredictedShapes, f_top_hz: float) -> tuple[float, float]:
    """Above the support modes, below the first flexible mode (or the top of the spectra)."""
    lo = max(3.0 * pred.support_hz, 20.0)
    flex = [m.frequency_hz for m in rig.flexible_modes]
    hi = 0.95 * min(flex) if flex else f_top_hz
    return lo, min(hi, f_top_hz)


def fit_band(freqs_hz: np.ndarray, h: np.ndarray, lo_hz: float, hi_hz: float, zeta: float,
             band_widths: float) -> slice:
    """Lines spanning the (up to six) most prominent resonances plus ``band_widths`` half-power widths."""
    i0, i1 = np.searchsorted(freqs_hz, [lo_hz, hi_hz])
    if i1 - i0 < 8:
        raise ProcessingError(f"no frequency lines between {lo_hz:.0f} and {hi_hz:.0f} Hz")
    # a few lines per half-power width are enough to see the peaks: a geometric grid
    grid = np.geomspace(freqs_hz[i0], freqs_hz[i1 - 1], max(8, int(np.log(hi_hz / lo_hz) / (0.25 * zeta))))
    lines = np.unique(np.clip(np.searchsorted(freqs_hz, grid), i0, i1 - 1))
    hs = h[:, lines]
    power = np.sum(hs.real**2 + hs.imag**2, axis=0)
    if not np.any(power > 0):
        raise ProcessingError(f"no response between {lo_hz:.0f} and {hi_hz:.0f} Hz")
    peaks, props = find_peaks(power, prominence=0.005 * float(power.max()))
    if not len(peaks):
        peaks = np.array([int(np.argmax(power))])
    else:
        peaks = peaks[np.argsort(props["prominences"])[::-1][: 2 * N_CONTACT_MODES]]
    f_peaks = freqs_hz[lines[peaks]]
    margin = band_widths * 2.0 * zeta
    lo = max(lo_hz, float(f_peaks.min()) * (1.0 - margin))
    hi = min(hi_hz, float(f_peaks.max()) * (1.0 + margin))
    a, b = np.searchsorted(freqs_hz, [lo, hi])
    return slice(int(a), int(b) + 1)


def _start_poles(f: np.ndarray, h: np.ndarray, rate: float, zeta: float) -> list[tuple[float, float]]:
    step = max(1, len(f) // 250)  # start poles only: a few hundred lines are plenty ...
    hs = h[:, ::step]
    if hs.shape[0] > N_CONTACT_MODES + 1:  # ... and the channels' dominant subspace holds every pole
        _, sv, vh = np.linalg.svd(hs, full_matrices=False)
        hs = sv[: N_CONTACT_MODES + 1, None] * vh[: N_CONTACT_MODES + 1]
    poles = lscf_poles(f[::step], hs, N_CONTACT_MODES, decay_rate_per_s=rate)
    modes = [pole_to_mode(p) for p in poles if p.imag > 0]
    good = sorted((fr, z) for fr, z in modes if f[0] <= fr <= f[-1] and 0 < z < MAX_DAMPING)
    power = np.sum(np.abs(h) ** 2, axis=0)
    while len(good) < N_CONTACT_MODES:  # fill from the strongest bins not yet covered
        taken = np.zeros(len(f), bool)
        for fr, _ in good:
            taken |= np.abs(f - fr) < 2.0 * zeta * fr
        free = np.where(taken, -np.inf, power)
        k = int(np.argmax(free))
        fr = float(f[k]) if np.isfinite(free[k]) else float(good[-1][0]) * (1.0 + 0.2 * zeta)
        good.append((fr, zeta))
        good.sort()
    return good


def _valid(fit: ModalFit, require_convergence: bool = True) -> bool:
    lo, hi = fit.band_hz
    return bool((fit.converged or not require_convergence)
                and np.all((fit.frequencies_hz > lo) & (fit.frequencies_hz < hi))
                and np.all((fit.damping_ratios > 1e-5) & (fit.damping_ratios < MAX_DAMPING))
                and np.all(np.isfinite(fit.frequency_std_hz)))


def channel_weights(noise: np.ndarray) -> np.ndarray:
    """1/σ per channel from each channel's noise floor: a noisier channel counts less."""
    sigma = np.maximum(noise, 1e-3 * float(np.median(noise)) + 1e-300)
    w = 1.0 / sigma
    return w / float(np.median(w))


def _widen(fit: ModalFit, live: np.ndarray, n_channels: int) -> ModalFit:
    """The fit with its constants spread back over all channels (dead ones 0)."""
    constants = np.zeros((len(fit.frequencies_hz), n_channels))
    constants[:, live] = fit.constants
    std = None
    if fit.constants_std is not None:
        std = np.full((len(fit.frequencies_hz), n_channels), np.inf)
        std[:, live] = fit.constants_std
    return replace(fit, constants=constants, constants_std=std)


def _trusted(fit: ModalFit, penalty: float, zeta: float) -> bool:
    """Every pole inside the band, well determined, plausibly damped (within a few times the rig's modal damping),
    of visible strength and worth its constants (likelihood ratio at RESOLUTION_LEVEL)."""
    damping = fit.damping_ratios
    if not _valid(fit) or np.any(damping > max(0.1, PLAUSIBLE_DAMPING * zeta)) \
            or np.any(damping < zeta / PLAUSIBLE_DAMPING):
        return False
    sharp = fit.frequency_std_hz < SHARPNESS * 2.0 * fit.damping_ratios * fit.frequencies_hz
    strength = np.sqrt(np.sum(fit.constants**2, axis=1)) / fit.damping_ratios  # peak response per mode
    strong = strength >= MIN_RELATIVE_STRENGTH * float(strength.max())
    return bool(np.all(sharp & strong & (fit.significance > penalty)))


def _apart(fit: ModalFit, tilt: Sequence[int], widen: Widen | None = None) -> bool:
    """The two tilt poles further apart than the test's limit in units of their difference's 1-σ (with the
    force noise's share when ``widen`` gives it)."""
    if widen is not None:
        fit = widen(fit)
    a, b = tilt
    gap = abs(fit.frequencies_hz[a] - fit.frequencies_hz[b])
    return bool(gap > -ndtri(RESOLUTION_LEVEL / 2) * math.hypot(fit.frequency_std_hz[a], fit.frequency_std_hz[b]))


def fit_contact_modes(freqs_hz: np.ndarray, h: np.ndarray, pred: PredictedShapes, live: np.ndarray, *,
                      search_hz: tuple[float, float], **kw: Any) -> ContactModes:
    """The contact modes in ``search_hz`` (see ``_fit_in_range`` for the keywords). A fitted mode whose shape is
    neither bounce nor tilt is cut out of the range when it lies apart beyond the contact modes and the fit
    repeated; one among them leaves the tilt pair unresolved. Either way it is named in ``stray_hz``."""
    modes = _fit_in_range(freqs_hz, h, pred, live, search_hz=search_hz, **kw)
    strays: tuple[float, ...] = ()
    while (r := _stray(modes)) is not None:
        strays = (*strays, float(modes.fit.frequencies_hz[r]))
        narrowed = _without(modes, r, search_hz) if len(strays) <= MAX_STRAY_CUTS else None
        if narrowed is None:
            return _disowned(modes, r, strays)
        try:
            modes = _fit_in_range(freqs_hz, h, pred, live, search_hz=narrowed, **kw)
        except ProcessingError:
            return _disowned(modes, r, strays)
        search_hz = narrowed
    return replace(modes, stray_hz=strays)


def _stray(modes: ContactModes) -> int | None:
    """The least tilt-like of the fitted non-bounce modes when its shape is neither tilt nor bounce."""
    cls = modes.classes
    if not cls.by_shape:
        return None
    odd = [i for i in cls.tilt if cls.tilt_fraction[i] < STRAY_SHARE and cls.bounce_mac[i] < STRAY_SHARE]
    return min(odd, key=lambda i: cls.tilt_fraction[i]) if odd else None


def _without(modes: ContactModes, r: int, search_hz: tuple[float, float]) -> tuple[float, float] | None:
    """The search range with stray mode ``r`` cut off at the geometric middle to its nearest contact mode, or
    None when it lies among them or too close to cut."""
    f, zeta = modes.fit.frequencies_hz, modes.fit.damping_ratios
    rest = [i for i in range(len(f)) if i != r]
    near = min(rest, key=lambda i: abs(f[i] - f[r]))
    outside = f[r] < min(f[rest]) or f[r] > max(f[rest])
    if not outside or abs(f[near] - f[r]) <= STRAY_GAP_WIDTHS * 2.0 * zeta[near] * f[near]:
        return None
    cut = math.sqrt(f[near] * f[r])
    return (max(search_hz[0], cut), search_hz[1]) if f[r] < f[near] else (search_hz[0], min(search_hz[1], cut))


def _disowned(modes: ContactModes, r: int, strays: tuple[float, ...]) -> ContactModes:
    """The fit with stray mode ``r`` taken out of the tilt pair, which is then unresolved."""
    cls = modes.classes
    tilt = tuple(i for i in cls.tilt if i != r) or cls.tilt
    return replace(modes, classes=replace(cls, tilt=tilt), pair_resolved=False, stray_hz=strays)


def _fit_in_range(
    freqs_hz: np.ndarray,
    h: np.ndarray,
    pred: PredictedShapes,
    live: np.ndarray,
    *,
    search_hz: tuple[float, float],
    decay_rate_per_s: float,
    noise_inflation: float,
    zeta: float,
    band_widths: float = 4.0,
    channel_noise: np.ndarray | None = None,
    widen: Callable[[ModalFit, slice], ModalFit] | None = None,
    line_step: int = 1,
) -> ContactModes:
    """Band, start poles, 3-mode fit; if the tilt pair is not clearly resolved, a 2-mode fit and split
    starts around its tilt, the best 3-mode fit kept only when the likelihood-ratio test prefers it.
    ``widen`` adds the force noise to a candidate's uncertainties before the tilt poles are compared;
    ``line_step`` keeps every so-many lines of the band (see ``Spectra.fit_line_step``)."""
    hl = h[live]
    band = fit_band(freqs_hz, hl, search_hz[0], search_hz[1], zeta, band_widths)
    band = slice(band.start, band.stop, line_step)
    noise_inflation = noise_inflation / line_step  # each kept line stands for line_step correlated ones
    f, hb = freqs_hz[band], hl[:, band]
    if len(f) < 4 * (N_CONTACT_MODES + 2):
        raise ProcessingError(f"the fit band {f[0]:.0f}-{f[-1]:.0f} Hz holds too few frequency lines")
    weights = np.ones(hb.shape[0]) if channel_noise is None else channel_weights(channel_noise[live])
    kw = {"decay_rate_per_s": decay_rate_per_s, "noise_inflation": noise_inflation, "channel_weights": weights}
    n_ch = h.shape[0]
    fit = _widen(fit_modes(f, hb, _start_poles(f, hb, decay_rate_per_s, zeta), max_iter=FIRST_FIT_ITER, **kw),
                 live, n_ch)
    n_live = int(live.sum())
    # likelihood-ratio limits (in σ² units; the window's line-to-line correlation scales the statistic):
    # a mode's constants on n_live channels; the second tilt pole: its frequency, damping and constants
    penalty = float(chdtri(n_live, RESOLUTION_LEVEL)) * noise_inflation
    pair_penalty = float(chdtri(n_live + 2, RESOLUTION_LEVEL)) * noise_inflation
    wid = (lambda fit_: widen(fit_, band)) if widen is not None else None
    classes = classify(fit.constants, fit.frequencies_hz, pred, live)
    if _trusted(fit, penalty, zeta) and _apart(fit, classes.tilt, wid):
        return ContactModes(fit, classes, True, band)
    if _valid(fit, require_convergence=False):  # a three-mode fit stopped early still gives good starts
        keep = sorted(np.argsort(fit.significance)[1:])
        start2 = [(float(fit.frequencies_hz[i]), float(fit.damping_ratios[i])) for i in keep]
    else:
        start2 = _two_starts(f, hb, decay_rate_per_s, zeta, pred)
    fit2 = _widen(fit_modes(f, hb, start2, **kw), live, n_ch)
    classes2 = classify(fit2.constants, fit2.frequencies_hz, pred, live)
    candidates = [(fit, classes)] if _trusted(fit, penalty, zeta) else []
    if _valid(fit2):
        ft, zt = float(fit2.frequencies_hz[classes2.tilt[0]]), float(fit2.damping_ratios[classes2.tilt[0]])
        fb, zb = float(fit2.frequencies_hz[classes2.bounce]), float(fit2.damping_ratios[classes2.bounce])
        step = 3  # the split starts are compared on every third line; the best one is refined on all
        trials = []
        for split in SPLITS:
            d = split * 2.0 * zt * ft
            trial = fit_modes(f[::step], hb[:, ::step], [(ft - d / 2, zt), (ft + d / 2, zt), (fb, zb)],
                              max_iter=TRIAL_ITER, **kw)
            if _valid(trial, require_convergence=False):
                trials.append(trial)
        if trials:
            pick = min(trials, key=lambda t: t.cost)
            cand = _widen(fit_modes(f, hb, list(zip(pick.frequencies_hz, pick.damping_ratios, strict=True)), **kw),
                          live, n_ch)
            if _trusted(cand, penalty, zeta):
                candidates.append((cand, classify(cand.constants, cand.frequencies_hz, pred, live)))
    if candidates:
        best, best_classes = min(candidates, key=lambda c: c[0].cost)
        gain = (fit2.cost - best.cost) / max(best.sigma2, 1e-300)
        if _apart(best, best_classes.tilt, wid) and gain > pair_penalty:
            return ContactModes(best, best_classes, True, band)
    if not _valid(fit2, require_convergence=False):
        raise ProcessingError(f"no contact modes could be fitted between {f[0]:.0f} and {f[-1]:.0f} Hz "
                              "(poles left the band or came out undamped)")
    return ContactModes(fit2, classes2, False, band, _hidden_split_std(fit, classes, fit2, classes2, wid))


def _hidden_split_std(fit3: ModalFit, classes3: Classification, fit2: ModalFit, classes2: Classification,
                      wid: Widen | None) -> float:
    """How large a tilt split the data could hide: the 1-σ of the split in the three-mode fit (its poles'
    spread when they sit together), or, without a usable three-mode fit, half the tilt's half-power width."""
    if _valid(fit3, require_convergence=False) and len(classes3.tilt) == 2:
        widened = wid(fit3) if wid is not None else fit3
        a, b = classes3.tilt
        return float(math.hypot(widened.frequency_std_hz[a], widened.frequency_std_hz[b]))
    t = classes2.tilt[0]
    return float(fit2.damping_ratios[t] * fit2.frequencies_hz[t])


def _two_starts(f: np.ndarray, h: np.ndarray, rate: float, zeta: float,
                pred: PredictedShapes) -> list[tuple[float, float]]:
    poles = lscf_poles(f, h, 2, decay_rate_per_s=rate)
    modes = sorted(pole_to_mode(p) for p in poles if p.imag > 0)
    good = [(fr, z) for fr, z in modes if f[0] <= fr <= f[-1] and 0 < z < MAX_DAMPING]
    if len(good) == 2:
        return good
    ratio = pred.tilt_hz / pred.bounce_hz
    k = int(np.argmax(np.sum(np.abs(h) ** 2, axis=0)))
    return [(float(f[k]), zeta), (float(f[k]) * ratio if ratio < 1 else float(f[k]) / ratio, zeta)]



