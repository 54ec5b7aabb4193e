"""Where does the model disagree with the data? Regions of load and contact case beyond the noise.

Residuals are r = ln(k_model/k_measured): r > 0 means the model is stiffer than measured. Each case's points
are split into low/middle/high load thirds; a third is reported when its mean residual exceeds the noise floor
and is significant (|mean| ≥ 3 standard errors); neighbouring thirds of one sign merge into one region.
Trends across cases (rail Ra, roller length, diameter, material) summarise how the disagreement varies.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from labctl.discrepancy.data import Dataset

LOAD_BINS = 3
SIGNIFICANT = 3.0


def _direction(mean: float) -> str:
    return "model_stiffer" if mean > 0 else "model_softer"


def _slope_per_decade(load_n: np.ndarray, r: np.ndarray) -> float:
    x = np.log10(load_n)
    if np.ptp(x) <= 0:
        return 0.0
    return float(np.polyfit(x, r, 1)[0])


def _trend(slope: float, sigma: float) -> str:
    if abs(slope) < sigma:
        return "flat"
    return "rises with load" if slope > 0 else "falls with load"


def locate(data: Dataset, residuals: np.ndarray, sigma: np.ndarray) -> list[dict[str, Any]]:
    """Load ranges per roller case where the residuals exceed the noise (σ per point), with sign and trend."""
    regions: list[dict[str, Any]] = []
    for c, sl in zip(data.cases, data.case_slices(), strict=True):
        r, s = residuals[sl], sigma[sl]
        order = np.argsort(c.load_n, kind="stable")
        cells = []
        for part in np.array_split(order, min(LOAD_BINS, order.size)):
            mean = float(r[part].mean())
            noise = float(np.sqrt(np.mean(s[part] ** 2)))
            flagged = abs(mean) > noise and abs(mean) >= SIGNIFICANT * noise / math.sqrt(part.size)
            cells.append((part, mean if flagged else 0.0))
        merged: list[np.ndarray] = []
        last_sign = 0.0
        for part, mean in cells:
            sign = float(np.sign(mean))
            if sign != 0 and sign == last_sign:
                merged[-1] = np.concatenate([merged[-1], part])
            elif sign != 0:
                merged.append(part)
            last_sign = sign
        for part in merged:
            loads, rr = c.load_n[part], r[part]
            mean = float(rr.mean())
            slope = _slope_per_decade(loads, rr)
            regions.append({
                **c.describe(),
                "load_n": [float(loads.min()), float(loads.max())],
                "load_per_length_n_per_mm": [float(loads.min() / c.case.roller.contact_length_m * 1e-3),
                                             float(loads.max() / c.case.roller.contact_length_m * 1e-3)],
                "n_points": int(part.size),
                "mean_residual": mean,
                "direction": _direction(mean),
                "slope_per_decade_load": slope,
                "trend": _trend(slope, float(np.sqrt(np.mean(s[part] ** 2)))),
            })
    return regions


CASE_VARIABLES = {
    "rail_ra_um": lambda d: d["rail_ra_um"],
    "contact_length_mm": lambda d: d["contact_length_mm"],
    "diameter_mm": lambda d: d["diameter_mm"],
}


def trends(data: Dataset, residuals: np.ndarray, sigma: float) -> list[dict[str, Any]]:
    """How the mean residual per case varies with each case descriptor that varies (and with load overall)."""
    out: list[dict[str, Any]] = []
    slope = _slope_per_decade(data.load_n, residuals)
    out.append({"variable": "load_n", "slope_per_decade": slope, "trend": _trend(slope, sigma)})
    info = [c.describe() for c in data.cases]
    means = np.array([float(residuals[sl].mean()) for sl in data.case_slices()])
    for name, get in CASE_VARIABLES.items():
        values = np.array([get(d) for d in info], dtype=float)
        if np.unique(values).size < 2:
            continue
        s = _slope_per_decade(values, means) if np.all(values > 0) else float(np.polyfit(values, means, 1)[0])
        out.append({"variable": name, "slope_per_decade": s,
                    "trend": "flat" if abs(s) < sigma else ("residual rises" if s > 0 else "residual falls")})
    materials = sorted({d["material"] for d in info})
    if len(materials) > 1:
        by = {m: float(np.mean([mu for d, mu in zip(info, means, strict=True) if d["material"] == m]))
              for m in materials}
        out.append({"variable": "material", "mean_residual": by})
    return out
