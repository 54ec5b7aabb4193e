"""A term's contribution to the model: ln k with the term minus ln k without it (the other parameters unchanged).

The posterior (``labctl.discrepancy.posterior``) bends each term's contribution with load to treat its form as
uncertain: a real effect whose law differs from the library's term is still that term, bent.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from labctl.discrepancy.data import Dataset
from labctl.discrepancy.measurement import MEASUREMENT
from labctl.discrepancy.model import Fit, predict_ln


def contribution(fit: Fit, data: Dataset, name: str) -> np.ndarray:
    """ln k of the fitted model minus ln k with term ``name`` left out (the other parameters unchanged)."""
    if name in MEASUREMENT:
        chain = tuple(t for t, n in zip(fit.chain, fit.spec.measurement, strict=True) if n != name)
        law = fit.law
    else:
        chain = fit.chain
        law = replace(fit.law, effects=tuple(e for e in fit.law.effects if e.name != name))
    with np.errstate(all="ignore"):
        d = fit.predict(data) - predict_ln(data, law, chain)
    return np.nan_to_num(d, nan=0.0, posinf=0.0, neginf=0.0)
