"""Measurement-side terms the baseline's own fitted depth takes up: the data cannot test them, whatever the
probabilities say.

In Tripp's line-contact law the load enters only through the logarithm of the contact half-width, as the
evaluation depth does, so a load-cell gain error changes every stiffness exactly as a depth change would: the
fitted depth absorbs it and the gain gets no probability it could earn. Checked on the data's own points, for any
baseline: a term is absorbed when the depth's column reproduces its own (a small step from no error) at every point.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from labctl.discrepancy.data import Dataset
from labctl.discrepancy.measurement import MEASUREMENT
from labctl.discrepancy.model import Fit, depth_column, predict_ln

ABSORBED_R2 = 0.999
"""Share of a term's column (d ln k) the depth's column reproduces, through the origin, for it to count as absorbed."""
PROBE_SHARE = 0.01
"""The step from no error each term is probed at, as a share of its fitted range."""


def absorbed_share(data: Dataset, base: Fit, name: str, depth: np.ndarray) -> float:
    """R² of measurement-side term ``name``'s column against the baseline's depth column ``depth``."""
    cls = MEASUREMENT[name]
    (parameter, (lo, hi)), = cls.BOUNDS.items()
    none = cls()
    probe = replace(none, **{parameter: getattr(none, parameter) + PROBE_SHARE * (hi - lo)})
    with np.errstate(all="ignore"):
        column = predict_ln(data, base.law, (*base.chain, probe)) - base.predict(data)
    if not np.all(np.isfinite(column)) or not np.any(column):
        return 0.0  # the probe leaves the law's domain somewhere (a load near zero): nothing shown absorbed
    slope = float(column @ depth) / float(depth @ depth)
    return float(1.0 - np.sum((column - slope * depth) ** 2) / np.sum(column**2))


def absorbed_reasons(data: Dataset, base: Fit) -> list[str]:
    """Why a measurement-side term cannot be tested on these data: the baseline's depth takes it up."""
    depth = depth_column(base, data)
    if depth is None or not np.any(depth):
        return []
    out = []
    for name in MEASUREMENT:
        share = absorbed_share(data, base, name, depth)
        if share >= ABSORBED_R2:
            out.append(f"{name}: it changes every stiffness as the baseline's evaluation depth does (R² {share:.4f} "
                       "over these points), so the fitted depth takes it up and the data cannot test it")
    return out
