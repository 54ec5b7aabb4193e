"""What a load step's identification returns (modes, stiffness, per-roller values, every impact's verdict)
and what a user may tune."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from labctl.processing.checks import CheckConfig, ImpactCheck
from labctl.processing.frf import WindowConfig


@dataclass(frozen=True)
class IdentifyConfig:
    """Everything the pipeline lets a user tune; defaults suit the paper's rig and hammer."""

    checks: CheckConfig = CheckConfig()
    window: WindowConfig = WindowConfig()
    band_widths: float = 4.0  # the fit band reaches this many half-power bandwidths past the outer modes
    search_hz: tuple[float, float] | None = None  # where contact modes are sought (default: from the rig)


@dataclass(frozen=True)
class Mode:
    """One identified contact mode: natural frequency and damping (window removed) with 1-σ, and its shape."""

    kind: str  # "bounce" or "tilt"
    frequency_hz: float
    frequency_std_hz: float
    damping_ratio: float
    damping_ratio_std: float
    shape: dict[str, float]  # real modal constant per channel, largest component +1
    bounce_mac: float  # MAC with the rig model's bounce shape over the live channels
    tilt_fraction: float  # share of the shape inside the model's tilt subspace
    coherence: float  # at this mode, over the used impacts


@dataclass
class Identification:
    """Result for one load step: modes, stiffness, the FRF they came from, and every impact's verdict."""

    bounce_hz: float
    bounce_hz_std: float
    bounce_damping_ratio: float
    bounce_damping_ratio_std: float
    tilt_hz: tuple[float, float]
    tilt_hz_std: tuple[float, float]
    tilt_pair_resolved: bool
    roller_stiffness_n_per_m: float
    roller_stiffness_std_n_per_m: float
    coherence_at_bounce: float
    impacts: list[ImpactCheck]
    frequencies_hz: np.ndarray
    h1: np.ndarray
    h2: np.ndarray
    coherence: np.ndarray
    channels: tuple[str, ...]
    modes: list[Mode]
    fs_hz: float
    window_decay_rate_per_s: float  # the exponential window's rate; its damping is removed from the modes
    fit_band_hz: tuple[float, float]
    dead_channels: tuple[str, ...] = ()
    dropped_channels: tuple[str, ...] = ()  # saturated in every impact: left out, the step goes on without them
    classified_by_shape: bool = True
    roller_only_stiffness_n_per_m: float | None = None
    roller_only_stiffness_std_n_per_m: float | None = None
    warnings: list[str] = field(default_factory=list)
    # per roller, in the rig file's roller order; the mean is roller_stiffness_n_per_m
    roller_stiffnesses_n_per_m: tuple[float, ...] = ()
    roller_stiffnesses_std_n_per_m: tuple[float, ...] = ()  # total (modal fit and rig parameters)
    # what tells rollers apart: the modal fit, the sensors' cross-axis coupling and the discs' inertia asymmetry
    roller_stiffnesses_fit_std_n_per_m: tuple[float, ...] = ()
    roller_stiffnesses_resolved: bool = False  # False: the tilt pair could not tell the rollers apart
    roller_stiffness_condition: float | None = None  # condition number of the per-roller inverse
    rollers_differing: tuple[int, ...] = ()  # 1-based rollers whose stiffness differs beyond its uncertainty
    roller_stiffness_budget_n_per_m: dict[str, float] = field(default_factory=dict)
    linearity: dict | None = None  # bounce frequency against peak force over the step's impacts
    small_blow: dict | None = None  # the modes' shift above their small-blow limit, carried in the σ
    blow_effect: dict | None = None  # that shift on the stiffness against its stated σ: is the hammer level too high?

    @property
    def accepted(self) -> list[int]:
        return [c.index for c in self.impacts if c.accepted]

    def to_dict(self) -> dict:
        """The ``labctl identify --json`` object (no spectra)."""
        out = {
            "bounce_hz": self.bounce_hz,
            "bounce_hz_std": self.bounce_hz_std,
            "bounce_damping_ratio": self.bounce_damping_ratio,
            "bounce_damping_ratio_std": self.bounce_damping_ratio_std,
            "tilt_hz": list(self.tilt_hz),
            "tilt_hz_std": list(self.tilt_hz_std),
            "tilt_pair_resolved": self.tilt_pair_resolved,
            "roller_stiffness_n_per_m": self.roller_stiffness_n_per_m,
            "roller_stiffness_std_n_per_m": self.roller_stiffness_std_n_per_m,
            "coherence_at_bounce": self.coherence_at_bounce,
            "impacts": [
                {"index": c.index, "accepted": c.accepted, "reasons": list(c.reasons),
                 "peak_force_n": c.peak_force_n, "pulse_width_s": c.pulse_width_s,
                 "second_hit_ratio": c.second_hit_ratio, "notes": list(c.notes)}
                for c in self.impacts
            ],
            "modes": [
                {"kind": m.kind, "frequency_hz": m.frequency_hz, "frequency_std_hz": m.frequency_std_hz,
                 "damping_ratio": m.damping_ratio, "damping_ratio_std": m.damping_ratio_std,
                 "bounce_mac": m.bounce_mac, "tilt_fraction": m.tilt_fraction, "coherence": m.coherence,
                 "shape": m.shape}
                for m in self.modes
            ],
            "channels": list(self.channels),
            "dead_channels": list(self.dead_channels),
            "dropped_channels": list(self.dropped_channels),
            "classified_by_shape": self.classified_by_shape,
            "fs_hz": self.fs_hz,
            "window_decay_rate_per_s": self.window_decay_rate_per_s,
            "fit_band_hz": list(self.fit_band_hz),
            "warnings": list(self.warnings),
        }
        out.update({
            "roller_stiffnesses_n_per_m": list(self.roller_stiffnesses_n_per_m),
            "roller_stiffnesses_std_n_per_m": list(self.roller_stiffnesses_std_n_per_m),
            "roller_stiffnesses_fit_std_n_per_m": list(self.roller_stiffnesses_fit_std_n_per_m),
            "roller_stiffnesses_mean_n_per_m": self.roller_stiffness_n_per_m,
            "roller_stiffnesses_resolved": self.roller_stiffnesses_resolved,
            "roller_stiffness_condition": self.roller_stiffness_condition,
            "rollers_differing": list(self.rollers_differing),
            "roller_stiffness_budget_n_per_m": dict(self.roller_stiffness_budget_n_per_m),
            "linearity": self.linearity,
            "small_blow": self.small_blow,
            "blow_effect": self.blow_effect,
        })
        if self.roller_only_stiffness_n_per_m is not None:
            out["roller_only_stiffness_n_per_m"] = self.roller_only_stiffness_n_per_m
            out["roller_only_stiffness_std_n_per_m"] = self.roller_only_stiffness_std_n_per_m
        return out
