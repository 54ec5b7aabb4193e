"""Per-roller stiffness from the identified bounce frequency, with its uncertainty carried through.

The inverse of the rig model (labctl.physics.rig: Eq. 4 with mass and K_setup from the rig file) gives k;
its sensitivity dk/df comes from the forward model, so σ_k = (dk/df)·σ_f. Optionally the two rail
indentations (Tripp, Eq. 2 at the evaluation depth) are removed in series to leave the roller alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from labctl.errors import ModelDomainError
from labctl.physics import RigConfig, TrippContact, roller_stiffness_from_bounce
from labctl.physics.rig import bounce_sensitivity, equal_roller_stiffness


@dataclass(frozen=True)
class Stiffness:
    """A stiffness (N/m) and its 1-σ uncertainty."""

    value_n_per_m: float
    std_n_per_m: float
    df_dk_hz_per_n_per_m: float = math.nan  # the bounce's slope there (from the bounce; NaN otherwise)


def stiffness_from_bounce(rig: RigConfig, bounce_frequency_hz: float, bounce_std_hz: float = 0.0) -> Stiffness:
    """Per-roller stiffness k (equal rollers) for this bounce frequency, and σ_k from σ_f."""
    if not (math.isfinite(bounce_frequency_hz) and bounce_frequency_hz > 0):
        roller_stiffness_from_bounce(rig, bounce_frequency_hz)  # raises the model's domain error
    k, df_dk = _equal_roller_stiffness(rig, float(bounce_frequency_hz))
    std = abs(bounce_std_hz / df_dk) if df_dk > 0 and math.isfinite(bounce_std_hz) else math.inf
    return Stiffness(k, std, df_dk)


_last: tuple[RigConfig, float, tuple[float, float]] | None = None


def _equal_roller_stiffness(rig: RigConfig, bounce_frequency_hz: float) -> tuple[float, float]:
    """``equal_roller_stiffness``, remembered for the last (rig object, frequency): a step asks twice (the
    blow's effect, then the result)."""
    global _last
    last = _last
    if last is not None and last[0] is rig and last[1] == bounce_frequency_hz:
        return last[2]
    out = equal_roller_stiffness(rig, bounce_frequency_hz)
    _last = (rig, bounce_frequency_hz, out)
    return out


def roller_only(measured: Stiffness, contact: TrippContact, load_n: float) -> Stiffness:
    """Remove the two rails' compliance (Tripp's Eq. 2) from the measured roller-path stiffness."""
    rails = float(contact.rail_compliance_m_per_n(load_n))
    remaining = 1.0 / measured.value_n_per_m - rails
    if not remaining > 0:
        raise ModelDomainError(
            f"the rails' compliance {rails:.3e} m/N at {load_n:g} N (Tripp, depth {contact.depth_m * 1e3:g} mm) "
            f"exceeds the measured {1.0 / measured.value_n_per_m:.3e} m/N: no roller-only stiffness is left"
        )
    k = 1.0 / remaining
    return Stiffness(k, (k / measured.value_n_per_m) ** 2 * measured.std_n_per_m)


BUDGET_TERMS = ("modal_fit", "disc_mass", "setup_stiffness", "rig_model")


@dataclass(frozen=True)
class StiffnessBudget:
    """1-σ contributions to a roller stiffness (N/m), named, and their total (with the mass–K_setup correlation)."""

    terms: dict[str, float]
    total_std_n_per_m: float


def stiffness_budget(rig: RigConfig, k_n_per_m: float, modal_std_n_per_m: float) -> StiffnessBudget:
    """The stiffness's uncertainty budget: the modal fit's share and the rig file's parameter uncertainties
    (disc mass, K_setup, their correlation, the rig model's relative error) carried through the rig model
    at the measured bounce frequency (k moves so that the bounce stays where it was measured)."""
    u = rig.uncertainty
    sens = bounce_sensitivity(rig, k_n_per_m)
    dk_dm = -sens.per_disc_mass / sens.per_roller_stiffness
    dk_dks = -sens.per_setup_stiffness / sens.per_roller_stiffness
    mass, setup = dk_dm * u.mass_std_kg, dk_dks * u.setup_stiffness_std_n_per_m
    terms = {"modal_fit": float(modal_std_n_per_m), "disc_mass": abs(float(mass)),
             "setup_stiffness": abs(float(setup)), "rig_model": float(u.model_rel * k_n_per_m)}
    var = sum(v * v for v in terms.values()) + 2.0 * u.mass_setup_correlation * mass * setup
    return StiffnessBudget(terms, math.sqrt(max(var, 0.0)))
