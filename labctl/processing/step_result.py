"""The last stage of a step's identification: its modes, stiffness and per-roller stiffness, and what to warn of.

Takes what the earlier stages hold (the screened impacts, the modal fit) and assembles the ``Identification``
every consumer stores and shows; no analysis is redone here.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from labctl.physics import RigConfig, TrippContact
from labctl.processing.frf import FrfEstimate
from labctl.processing.identification import Identification, IdentifyConfig, Mode
from labctl.processing.rollers import RollerStiffnesses, per_roller
from labctl.processing.search import ContactModes
from labctl.processing.shapes import signed_shape
from labctl.processing.stiffness import Stiffness, roller_only, stiffness_budget, stiffness_from_bounce

if TYPE_CHECKING:
    from labctl.processing.identify import Screened, StepFit

MODE_LINES = 2
"""A mode's coherence is read within ± this many spectral lines of its frequency."""


def mode_bins(freqs: np.ndarray, frequency_hz: float) -> np.ndarray:
    """The spectral lines within ±``MODE_LINES`` of a frequency."""
    k = int(np.searchsorted(freqs, frequency_hz))
    return np.arange(max(k - MODE_LINES, 0), min(k + MODE_LINES + 1, len(freqs)))


def mode_coherence(frf: FrfEstimate, modes: ContactModes) -> list[float]:
    """Coherence within ±``MODE_LINES`` lines of each mode, channels weighted by the mode's constants²."""
    out = []
    for r, fr in enumerate(modes.fit.frequencies_hz):
        w = modes.fit.constants[r] ** 2
        coh = frf.coherence[:, mode_bins(frf.frequencies_hz, fr)].mean(axis=1)
        out.append(float(w @ coh / w.sum()) if w.sum() > 0 else 0.0)
    return out


def _modes(modes: ContactModes, names: tuple[str, ...], coh: list[float]) -> list[Mode]:
    """The bounce first, then the tilt modes, each with its shape over the channels."""
    fit, cls = modes.fit, modes.classes
    return [
        Mode("bounce" if r == cls.bounce else "tilt", float(fit.frequencies_hz[r]), float(fit.frequency_std_hz[r]),
             float(fit.damping_ratios[r]), float(fit.damping_std[r]),
             dict(zip(names, (float(v) for v in signed_shape(fit.constants[r])), strict=True)),
             float(cls.bounce_mac[r]), float(cls.tilt_fraction[r]), coh[r])
        for r in [cls.bounce, *cls.tilt]
    ]


def _per_roller_std(rollers: RollerStiffnesses, k: Stiffness, rig_share2: float) -> tuple[float, ...]:
    """Each roller's σ: its modal fit's, plus the rig's share of the step's σ at that roller's stiffness."""
    return tuple(math.hypot(s, v / k.value_n_per_m * math.sqrt(rig_share2))
                 for s, v in zip(rollers.std_n_per_m, rollers.values_n_per_m, strict=True))


def _warnings(step: Screened, fit: StepFit, cfg: IdentifyConfig, coherence_at_bounce: float,
              warnings: list[str]) -> tuple[str, ...]:
    """Appends what the reader must know about the fit to ``warnings``; returns the dead channels."""
    modes = fit.modes
    if coherence_at_bounce < cfg.checks.min_coherence:
        warnings.append(f"coherence at the bounce {coherence_at_bounce:.3f} is below {cfg.checks.min_coherence:g}")
    if modes.stray_hz:
        warnings.append(f"mode(s) at {', '.join(f'{f:.1f}' for f in modes.stray_hz)} Hz in the contact-mode range have "
                        "neither the bounce's nor the tilt's shape (a rail, mount or support resonance?): not "
                        "taken for contact modes")
    if not modes.classes.by_shape:
        warnings.append("the live channels cannot separate bounce from tilt shapes: assigned by frequency order")
    dead = tuple(n for n, ok in zip(step.names, fit.live, strict=True) if not ok and n not in step.dropped)
    if dead:
        warnings.append(f"dead channel(s) left out: {', '.join(dead)}")
    return dead


def step_result(step: Screened, fit: StepFit, rig: RigConfig, cfg: IdentifyConfig, contact: TrippContact | None,
                load_n: float | None, warnings: list[str], blow_dependent: bool = False) -> Identification:
    """The step's ``Identification`` from its screened impacts and modal fit; ``contact`` and ``load_n`` add the
    roller-only stiffness; ``blow_dependent``: the blow's effect on the bounce is material (per-roller caveat)."""
    modes, frf, names = fit.modes, fit.frf, step.names
    mf, cls = modes.fit, modes.classes
    coh = mode_coherence(frf, modes)
    b = cls.bounce
    tilt = list(cls.tilt) * (2 if len(cls.tilt) == 1 else 1)
    k_eq = stiffness_from_bounce(rig, float(mf.frequencies_hz[b]), float(mf.frequency_std_hz[b]))
    rollers = per_roller(rig, names, fit.live, modes, k_eq, warnings, blow_dependent)
    budget = stiffness_budget(rig, rollers.mean_n_per_m,
                              rollers.mean_std_n_per_m if rollers.resolved else k_eq.std_n_per_m)
    k = Stiffness(rollers.mean_n_per_m, budget.total_std_n_per_m)
    rig_share2 = max(budget.total_std_n_per_m**2 - budget.terms["modal_fit"] ** 2, 0.0)
    alone: Stiffness | None = roller_only(k, contact, load_n) if contact is not None and load_n is not None else None
    dead = _warnings(step, fit, cfg, coh[b], warnings)
    return Identification(
        bounce_hz=float(mf.frequencies_hz[b]),
        bounce_hz_std=float(mf.frequency_std_hz[b]),
        bounce_damping_ratio=float(mf.damping_ratios[b]),
        bounce_damping_ratio_std=float(mf.damping_std[b]),
        tilt_hz=(float(mf.frequencies_hz[tilt[0]]), float(mf.frequencies_hz[tilt[1]])),
        tilt_hz_std=(float(mf.frequency_std_hz[tilt[0]]), float(mf.frequency_std_hz[tilt[1]])),
        tilt_pair_resolved=modes.pair_resolved,
        roller_stiffness_n_per_m=k.value_n_per_m,
        roller_stiffness_std_n_per_m=k.std_n_per_m,
        coherence_at_bounce=coh[b],
        impacts=step.checks,
        frequencies_hz=frf.frequencies_hz,
        h1=frf.h1,
        h2=frf.h2,
        coherence=frf.coherence,
        channels=names,
        modes=_modes(modes, names, coh),
        fs_hz=step.fs_hz,
        window_decay_rate_per_s=fit.spectra.decay_rate_per_s,
        fit_band_hz=mf.band_hz,
        dead_channels=dead,
        dropped_channels=step.dropped,
        classified_by_shape=cls.by_shape,
        roller_only_stiffness_n_per_m=alone.value_n_per_m if alone else None,
        roller_only_stiffness_std_n_per_m=alone.std_n_per_m if alone else None,
        warnings=warnings,
        roller_stiffnesses_n_per_m=rollers.values_n_per_m,
        roller_stiffnesses_std_n_per_m=_per_roller_std(rollers, k, rig_share2),
        roller_stiffnesses_fit_std_n_per_m=rollers.std_n_per_m,
        roller_stiffnesses_resolved=rollers.resolved,
        roller_stiffness_condition=rollers.condition,
        rollers_differing=tuple(i + 1 for i in rollers.differing),
        roller_stiffness_budget_n_per_m=dict(budget.terms),
    )
