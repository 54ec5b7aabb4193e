"""The load step's pipeline: impact checks → windowed FRF → contact modes → bounce/tilt → stiffness.

Every impact is checked on its own (double hit, overload, pulse width, force); the accepted ones are
averaged into H1/H2/coherence; the contact modes are fitted and classified by shape; an impact that spoils
the coherence at the bounce is rejected (``low_coherence``) and the step is redone without it. The bounce
frequency gives the per-roller stiffness through the rig model (Eq. 4).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from labctl.errors import InputError
from labctl.physics import RigConfig, TrippContact
from labctl.processing.blow import blow_effect
from labctl.processing.channels import (
    channel_noise,
    live_channels,
    rail_touches,
    saturated_channels,
    without_overload_of,
)
from labctl.processing.checks import LOW_COHERENCE, CheckConfig, ImpactCheck, check_impact
from labctl.processing.errors import ProcessingError
from labctl.processing.force_noise import ForceNoiseWidener
from labctl.processing.frf import (
    FrfEstimate,
    Spectra,
    analysed_samples,
    coherence_at,
    estimate_frf,
    impact_spectra,
    response_buffer,
)
from labctl.processing.identification import Identification, IdentifyConfig
from labctl.processing.linearity import small_blow_limit, step_linearity, widened
from labctl.processing.search import ContactModes, fit_contact_modes, search_range_hz
from labctl.processing.shapes import PredictedShapes, predicted_shapes
from labctl.processing.step_result import mode_bins, mode_coherence, step_result


def _inputs(force_n: np.ndarray, accel: np.ndarray, fs_hz: float, channels: Sequence[str],
            rig: RigConfig) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    f = np.asarray(force_n, dtype=float)
    a = np.asarray(accel, dtype=float)
    if f.ndim == 1:
        f, a = f[None], a[None]
    if f.ndim != 2 or a.ndim != 3 or a.shape[0] != f.shape[0] or a.shape[2] != f.shape[1]:
        raise InputError(f"force has shape {f.shape} and accel {a.shape}; expected (n_impacts, n_samples) and "
                         "(n_impacts, n_channels, n_samples)")
    names = tuple(str(c) for c in channels)
    if len(names) != a.shape[1]:
        raise InputError(f"{len(names)} channel names for {a.shape[1]} response channels")
    unknown = [c for c in names if c not in rig.channels]
    if unknown:
        raise InputError(f"channel(s) {', '.join(unknown)} are not sensors of rig '{rig.name}' "
                         f"(expected names among {', '.join(rig.channels)})")
    if not (math.isfinite(fs_hz) and fs_hz > 0):
        raise InputError(f"sample rate {fs_hz!r} Hz: expected a positive number")
    return f, a, names


def _bounce_coherence(spectra: Spectra, used: list[int], modes: ContactModes) -> float:
    """Coherence at the bounce over the impacts ``used`` (from their spectra)."""
    r = modes.classes.bounce
    bins = mode_bins(spectra.frequencies_hz, modes.fit.frequencies_hz[r])
    weights = np.repeat((modes.fit.constants[r] ** 2)[:, None], len(bins), axis=1)
    return coherence_at(spectra, used, bins, weights)


def _coherence_check(spectra: Spectra, frf: FrfEstimate, used: list[int], modes: ContactModes,
                     min_coherence: float, protected: frozenset[int] = frozenset()) -> int | None:
    """The impact whose removal lifts the coherence at the bounce above ``min_coherence`` (if one does).

    Only the bounce (the stiffness comes from it) is judged: the hammer's scatter over the disc changes how
    the near-degenerate tilt pair is excited from blow to blow, which lowers their coherence legitimately.
    """
    if mode_coherence(frf, modes)[modes.classes.bounce] >= min_coherence or len(used) < 3:
        return None
    candidates = [i for i in used if i not in protected]  # the operator's accepted impacts stay
    if not candidates:
        return None
    without = [_bounce_coherence(spectra, [u for u in used if u != i], modes) for i in candidates]
    best = int(np.argmax(without))
    return candidates[best] if without[best] >= min_coherence else None


def _fit(frf: FrfEstimate, spectra: Spectra, pred: PredictedShapes, live: np.ndarray, search: tuple[float, float],
         zeta: float, cfg: IdentifyConfig, noise: np.ndarray, widen: ForceNoiseWidener) -> ContactModes:
    """The contact modes, their uncertainties including the force noise."""
    modes = fit_contact_modes(frf.frequencies_hz, frf.h1, pred, live, search_hz=search,
                              decay_rate_per_s=spectra.decay_rate_per_s, noise_inflation=spectra.noise_inflation,
                              zeta=zeta, band_widths=cfg.band_widths, channel_noise=noise, widen=widen,
                              line_step=spectra.fit_line_step)
    return replace(modes, fit=widen(modes.fit, modes.band))


@dataclass
class Screened:
    """A step's impacts after the automatic checks and the operator's verdicts: what the modal fit may use."""

    force: np.ndarray
    accel: np.ndarray
    fs_hz: float
    names: tuple[str, ...]
    buffer: np.ndarray
    """The analysed span of the responses (up to twice their ring-down when the window trims to the decay)."""
    checks: list[ImpactCheck]
    accepted: list[int]
    """Indices of the accepted impacts."""
    dropped: tuple[str, ...]
    """Channels saturated in every impact, left out of the step."""

    def peak_forces_n(self, used: list[int]) -> list[float]:
        return [self.checks[self.accepted[u]].peak_force_n for u in used]


@dataclass
class StepFit:
    """The modal fit of a step: spectra of the accepted impacts, the FRF over those used, and its contact modes."""

    spectra: Spectra
    frf: FrfEstimate
    used: list[int]
    """Positions in ``Screened.accepted`` of the impacts the FRF averages."""
    live: np.ndarray
    noise: np.ndarray
    """Each channel's noise (the fit's weights)."""
    sigma_f: np.ndarray
    """Force noise per accepted impact, N."""
    modes: ContactModes
    widen: ForceNoiseWidener
    """The force noise's share of each mode's σ, for this FRF."""


def _screen(force_n: np.ndarray, accel_m_per_s2: np.ndarray, fs_hz: float, channels: Sequence[str], rig: RigConfig,
            cfg: IdentifyConfig, accel_ranges: float | Sequence[float] | None, force_range_n: float | None,
            forced: Sequence[bool | None] | None) -> Screened:
    """Stage 1: check every impact on its own, drop channels saturated throughout, apply the operator's verdicts."""
    force, accel, names = _inputs(force_n, accel_m_per_s2, fs_hz, channels, rig)
    # the span analysed: the records up to twice their ring-down (checks look at what the spectra will hold)
    buf = response_buffer(accel, analysed_samples(accel, fs_hz) if cfg.window.trim_to_decay else None)
    top, bottom = buf[:, 1:].max(axis=-1), buf[:, 1:].min(axis=-1)
    checks = [check_impact(force[i], accel[i], fs_hz, index=i, accel_ranges=accel_ranges, force_range_n=force_range_n,
                           config=cfg.checks, channels=names, extremes=(top[i], bottom[i]))
              for i in range(force.shape[0])]
    checks = rail_touches(checks, accel, names)
    dropped = saturated_channels(checks, names)
    if dropped:
        checks = [without_overload_of(c, dropped) for c in checks]
    if forced is not None:
        if len(forced) != len(checks):
            raise InputError(f"{len(forced)} operator verdicts for {len(checks)} impacts")
        checks = [_operator_verdict(c, f) for c, f in zip(checks, forced, strict=True)]
    accepted = [c.index for c in checks if c.accepted]
    if not accepted:
        summary = "; ".join(f"impact {c.index}: {', '.join(c.reasons)}" for c in checks)
        raise ProcessingError(f"all {len(checks)} impacts rejected ({summary})")
    return Screened(force, accel, fs_hz, names, buf, checks, accepted, dropped)


def _fit_step(step: Screened, rig: RigConfig, cfg: IdentifyConfig, forced: Sequence[bool | None] | None) -> StepFit:
    """Stage 2: spectra and FRF of the accepted impacts, the contact modes; one impact that spoils the coherence at
    the bounce is rejected (in ``step.checks``) and the fit redone without it."""
    names, accepted, checks = step.names, step.accepted, step.checks
    pred = predicted_shapes(rig, names)
    pulses = [(checks[i].pulse_start, checks[i].pulse_end, checks[i].force_noise_n) for i in accepted]
    window = cfg.window
    if window.max_frequency_hz is not None and window.max_frequency_hz < 1.25 * pred.max_bounce_hz:
        window = replace(window, max_frequency_hz=1.25 * pred.max_bounce_hz)  # a stiff rig's modes stay in view
    segments = [checks[i].further_pulses for i in accepted]
    spectra = impact_spectra(step.force, step.accel, step.fs_hz, pulses, window, use=accepted, buffer=step.buffer,
                             segments=segments)
    used = list(range(len(accepted)))
    frf = estimate_frf(spectra, used)
    live = live_channels(frf) & np.array([n not in step.dropped for n in names])
    if not live.any():
        raise ProcessingError(f"no response channel left: {', '.join(step.dropped)} saturated in every impact, "
                              "the others flat")
    noise = channel_noise(step.accel, accepted)
    search = cfg.search_hz or search_range_hz(rig, pred, float(spectra.frequencies_hz[-1]))
    zeta = rig.modal_damping_ratio
    sigma_f = np.array([checks[i].force_noise_n for i in accepted])
    widen = ForceNoiseWidener(frf, spectra, used, sigma_f, live, noise)
    modes = _fit(frf, spectra, pred, live, search, zeta, cfg, noise, widen)
    protected = frozenset(k for k, i in enumerate(accepted) if forced is not None and forced[i])
    drop = _coherence_check(spectra, frf, used, modes, cfg.checks.min_coherence, protected)
    if drop is not None:
        i = accepted[drop]
        checks[i] = checks[i].rejected_for(LOW_COHERENCE, "coherence at the bounce rises above "
                                           f"{cfg.checks.min_coherence:g} without this impact")
        used.remove(drop)
        frf = estimate_frf(spectra, used)
        widen = ForceNoiseWidener(frf, spectra, used, sigma_f, live, noise)
        modes = _fit(frf, spectra, pred, live, search, zeta, cfg, noise, widen)
    return StepFit(spectra, frf, used, live, noise, sigma_f, modes, widen)


def identify(
    force_n: np.ndarray,
    accel_m_per_s2: np.ndarray,
    fs_hz: float,
    channels: Sequence[str],
    rig: RigConfig,
    *,
    accel_ranges: float | Sequence[float] | None = None,
    force_range_n: float | None = None,
    config: IdentifyConfig | CheckConfig | None = None,
    contact: TrippContact | None = None,
    load_n: float | None = None,
    forced: Sequence[bool | None] | None = None,
) -> Identification:
    """Identify one load step from its impacts; ``contact`` and ``load_n`` add the roller-only stiffness.

    ``forced`` holds the operator's verdict per impact (None: the checks decide): an impact forced True is
    used even when a check flags it (and is never dropped for coherence), one forced False is never used.
    Stages: screen the impacts, fit the contact modes, judge the blow's effect, assemble the result.

    Raises ProcessingError when no impact or no mode is usable.
    """
    cfg = config if isinstance(config, IdentifyConfig) else IdentifyConfig(checks=config or CheckConfig())
    step = _screen(force_n, accel_m_per_s2, fs_hz, channels, rig, cfg, accel_ranges, force_range_n, forced)
    fit = _fit_step(step, rig, cfg, forced)
    warnings: list[str] = []
    if step.dropped:
        warnings.append(f"channel(s) {', '.join(step.dropped)} saturated in every impact: dropped, the step goes on "
                        "with the other channels")
    peaks = step.peak_forces_n(fit.used)
    lin = step_linearity(fit.modes, fit.spectra, fit.used, peaks, fit.sigma_f, fit.live, fit.noise, fit.widen)
    small_blow = small_blow_limit(fit.modes, fit.spectra, fit.used, lin, fs_hz)
    b = fit.modes.classes.bounce
    blow = blow_effect(rig, float(fit.modes.fit.frequencies_hz[b]), float(fit.modes.fit.frequency_std_hz[b]), lin,
                       small_blow, peaks)
    if small_blow is not None and small_blow.significant:
        fit.modes = widened(fit.modes, small_blow)  # the σ covers the small-blow limit whether or not that is material
    if blow is not None and blow.warning():
        warnings.append(blow.warning())
    material = blow is not None and blow.material
    result = step_result(step, fit, rig, cfg, contact, load_n, warnings, blow_dependent=material)
    result.linearity = lin.to_dict() if lin is not None else None
    result.small_blow = small_blow.to_dict() if small_blow is not None else None
    result.blow_effect = blow.to_dict() if blow is not None else None
    return result


def _operator_verdict(check: ImpactCheck, accept: bool | None) -> ImpactCheck:
    """An impact's check with the operator's verdict applied (None leaves the checks' verdict)."""
    if accept is None:
        return check
    if accept:
        return replace(check, accepted=True, notes=(*check.notes, "accepted by the operator"))
    return check.rejected_for(OPERATOR_REJECTED, "rejected by the operator")


OPERATOR_REJECTED = "operator_rejected"
