"""Measurement-side explanations: errors of the measurement chain or of the inputs, never physics of the contact.

A load-cell gain or offset makes the recorded load differ from the true one; a wrong Young's modulus (or a
unit slip in it) makes the model's E* wrong. They change what the model is evaluated at, not the contact law,
so the workflow reports them apart from the physical effects (JSON ``measurement_effects``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import ClassVar, Protocol

import numpy as np

from labctl.physics.contact import FloatArray
from labctl.physics.effects import BoundedParams, ContactCase

TRIPP_DEPTH_RANGE_M = (0.7e-3, 10e-3)
"""Where Tripp's evaluation depth is physically sensible for rails of a few mm: a fitted depth outside it means
the baseline's nuisance parameter absorbs something else (typically a modulus/unit or load-gain error)."""


class MeasurementTerm(Protocol):
    name: ClassVar[str]
    BOUNDS: ClassVar[dict[str, tuple[float, float]]]

    def transform(self, case: ContactCase, load_n: FloatArray) -> tuple[ContactCase, FloatArray]: ...

    def parameters(self) -> dict[str, float]: ...


@dataclass(frozen=True)
class LoadGain(BoundedParams):
    """The load cell reads ``gain`` × the true load: the model is evaluated at F_recorded / gain."""

    gain: float = 1.0
    name: ClassVar[str] = "load_gain"
    BOUNDS: ClassVar[dict[str, tuple[float, float]]] = {"gain": (0.7, 1.4)}

    def transform(self, case: ContactCase, load_n: FloatArray) -> tuple[ContactCase, FloatArray]:
        return case, load_n / self.gain


@dataclass(frozen=True)
class LoadOffset(BoundedParams):
    """The load cell reads the true load plus ``offset_n`` (a zero error): true load F_recorded − offset."""

    offset_n: float = 0.0
    name: ClassVar[str] = "load_offset"
    BOUNDS: ClassVar[dict[str, tuple[float, float]]] = {"offset_n": (-60.0, 60.0)}
    LOOK_ALIKE: ClassVar[str] = ("a hard coating or film on the rails whose effect fades as the contact widens past "
                                 "its thickness: read the load cell at no load before correcting its zero")

    def transform(self, case: ContactCase, load_n: FloatArray) -> tuple[ContactCase, FloatArray]:
        true = load_n - self.offset_n
        return case, np.where(true > 0, true, np.nan)


@dataclass(frozen=True)
class ModulusScale(BoundedParams):
    """Both bodies' true Young's moduli are ``scale`` × the ones the model was given (a wrong catalogue value
    or a unit slip): the model is evaluated with scaled moduli."""

    scale: float = 1.0
    name: ClassVar[str] = "modulus_scale"
    BOUNDS: ClassVar[dict[str, tuple[float, float]]] = {"scale": (0.6, 1.6)}

    def transform(self, case: ContactCase, load_n: FloatArray) -> tuple[ContactCase, FloatArray]:
        r = case.roller
        roller = replace(r, material=replace(r.material, youngs_modulus_pa=r.material.youngs_modulus_pa * self.scale))
        rail = replace(case.rail, youngs_modulus_pa=case.rail.youngs_modulus_pa * self.scale)
        return replace(case, roller=roller, rail=rail), load_n


MEASUREMENT: dict[str, type] = {cls.name: cls for cls in (LoadGain, LoadOffset, ModulusScale)}
"""Measurement-side terms by name (never physical effects)."""
