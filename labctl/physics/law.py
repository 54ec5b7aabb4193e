"""A contact law: a baseline contact model plus ordered effect terms, evaluated for any contact case.

This is the one object that both the simulated rig (its hidden "world") and the discrepancy workflow
(its fitted model) evaluate, so the twin and the analysis share every formula.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from labctl.physics.contact import ContactModel, FloatArray, as_load
from labctl.physics.effects import ContactCase, Effect
from labctl.physics.empirical import FITS, EmpiricalFit
from labctl.physics.hertz import HertzBallContact
from labctl.physics.palmgren import PalmgrenContact
from labctl.physics.tripp import DEFAULT_DEPTH_M, TrippContact

Baseline = Literal["tripp", "hertz", "palmgren", "fit-ra0.2", "fit-ra0.03"]
BASELINES: tuple[str, ...] = ("tripp", "hertz", "palmgren", "fit-ra0.2", "fit-ra0.03")


def baseline_model(baseline: str, case: ContactCase, depth_m: float = DEFAULT_DEPTH_M) -> ContactModel:
    """The named baseline contact model for a contact case (a ball for ``hertz``: the roller's diameter)."""
    if baseline == "tripp":
        return TrippContact(case.roller, case.rail, depth_m)
    if baseline == "hertz":
        return HertzBallContact(case.roller.diameter_m, case.roller.material, case.rail)
    if baseline == "palmgren":
        return PalmgrenContact(case.roller.contact_length_m)
    if baseline in FITS:
        return EmpiricalFit(FITS[baseline], case.roller.contact_length_m)
    raise ValueError(f"unknown baseline {baseline!r}; expected one of {', '.join(BASELINES)}")


@dataclass(frozen=True)
class ContactLaw:
    """Baseline model (with Tripp's evaluation depth) followed by effect terms applied in order."""

    baseline: str = "tripp"
    depth_m: float = DEFAULT_DEPTH_M
    effects: tuple[Effect, ...] = field(default=())

    def __post_init__(self) -> None:
        if self.baseline not in BASELINES:
            raise ValueError(f"unknown baseline {self.baseline!r}; expected one of {', '.join(BASELINES)}")

    def stiffness_n_per_m(self, case: ContactCase, load_n: ArrayLike, baseline_n_per_m: FloatArray | None = None
                          ) -> FloatArray:
        """The law's stiffness; ``baseline_n_per_m``: the baseline's stiffness at these loads, when a caller that
        evaluates many laws on one baseline (a fit's Jacobian) has it already."""
        f = as_load(load_n, self.baseline)
        k = np.asarray(baseline_model(self.baseline, case, self.depth_m).stiffness_n_per_m(f), dtype=float) \
            if baseline_n_per_m is None else baseline_n_per_m
        for effect in self.effects:
            k = effect.apply(case, f, k)
        return k

    def with_effect(self, effect: Effect) -> ContactLaw:
        return replace(self, effects=(*self.effects, effect))

    @property
    def effect_names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.effects)
