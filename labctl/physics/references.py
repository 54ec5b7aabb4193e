"""Reference model curves to show beside measured stiffness: Tripp and the fit for the rails' roughness, or Hertz."""

from __future__ import annotations

import contextlib

import numpy as np
from numpy.typing import ArrayLike

from labctl.errors import ModelDomainError
from labctl.physics.effects import ContactCase
from labctl.physics.law import baseline_model

ROUGH_RAIL_RA_M = 0.1e-6


def fit_for_rail(rail_ra_m: float) -> str:
    """The paper's fit made for rails like these: Eq. 5 (Ra 0.2 µm) or Eq. 6 (Ra 0.03 µm)."""
    return "fit-ra0.2" if rail_ra_m >= ROUGH_RAIL_RA_M else "fit-ra0.03"


def model_curve(name: str, case: ContactCase, load_n: ArrayLike) -> np.ndarray:
    """A baseline model's stiffness at the loads; NaN where it is not defined (e.g. Eq. 5 at very low load),
    so a curve can still be drawn."""
    f = np.atleast_1d(np.asarray(load_n, dtype=float))
    model = baseline_model(name, case)
    values = np.full(f.shape, np.nan)
    for i, load in enumerate(f):
        with contextlib.suppress(ModelDomainError):
            values[i] = float(model.stiffness_n_per_m(load))
    return values


def reference_curves(case: ContactCase, kind: str, load_n: ArrayLike) -> dict[str, np.ndarray]:
    """Model stiffness at the given loads: ``hertz`` for balls; ``tripp`` and the matching fit for rollers."""
    names = ("hertz",) if kind == "ball" else ("tripp", fit_for_rail(case.rail_ra_m))
    return {name: model_curve(name, case, load_n) for name in names}
