"""Fit the spring curve (``labctl.physics.springs``) to a characterisation's knob angles and load-cell loads.

The preload is the mean of the readings before any turn. The slack is found on a fine grid (the model is not
smooth in it); at each slack the rate, curvature and hysteresis are a linear least-squares fit. Points whose
spring load is below 5 % of the largest are left out (there the friction band is clipped at zero force, which
the curve does not model). The covariance comes from the Jacobian at the optimum, scaled by the residual variance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from labctl.errors import InputError
from labctl.physics.springs import PARAMETERS, SpringCurve

SLACK_GRID_DEG = 0.05
MIN_POINTS = 8
LOW_FRACTION = 0.05


@dataclass(frozen=True)
class SpringData:
    """A characterisation's readings: knob angle (°), load per roller (N), +1 loading / −1 unloading."""

    angle_deg: np.ndarray
    load_n: np.ndarray
    direction: np.ndarray
    source: str = ""


def _design(angle: np.ndarray, direction: np.ndarray, slack: float) -> np.ndarray:
    u = np.maximum(0.0, angle - slack)
    return np.column_stack([u, u * u, -0.5 * direction])


def fit_spring_curve(data: SpringData) -> SpringCurve:
    """The knob-angle → load curve with its covariance; an ``InputError`` names what the data cannot give."""
    a, f, d = (np.asarray(x, dtype=float) for x in (data.angle_deg, data.load_n, data.direction))
    zero = np.isclose(a, 0.0) & (d > 0)
    if zero.sum() < 2:
        raise InputError(f"{data.source}: a spring characterisation needs at least two readings at knob angle 0 "
                         "(the preload) before the first turn")
    preload = float(f[zero].mean())
    preload_std = float(f[zero].std(ddof=1) / math.sqrt(zero.sum()))
    if not ((d < 0).any() and (d > 0).any()):
        raise InputError(f"{data.source}: a spring characterisation needs loading and unloading readings "
                         "(the hysteresis cannot be fitted from one branch)")
    keep = f - preload > LOW_FRACTION * float(np.max(f - preload))
    if keep.sum() < MIN_POINTS:
        raise InputError(f"{data.source}: only {int(keep.sum())} readings above the preload; the spring curve needs "
                         f"at least {MIN_POINTS}")
    ak, fk, dk = a[keep], f[keep] - preload, d[keep]
    best: tuple[float, float, np.ndarray] | None = None
    for slack in np.arange(0.0, float(ak.min()), SLACK_GRID_DEG):
        x = _design(ak, dk, slack)
        coef, *_ = np.linalg.lstsq(x, fk, rcond=None)
        sse = float(np.sum((fk - x @ coef) ** 2))
        if best is None or sse < best[0]:
            best = (sse, float(slack), coef)
    assert best is not None
    sse, slack, (rate, curv, hyst) = best
    dof = keep.sum() - 4
    sigma2 = sse / dof
    u = np.maximum(0.0, ak - slack)
    jac = np.column_stack([u, u * u, -0.5 * dk, -(rate + 2 * curv * u)])
    cov = sigma2 * np.linalg.pinv(jac.T @ jac)
    if rate <= 0:
        raise InputError(f"{data.source}: the fitted spring rate is {rate:.3g} N/° (not positive): do the loads "
                         "rise with the knob angle?")
    return SpringCurve(preload_n=preload, rate_n_per_deg=float(rate), curvature_n_per_deg2=float(curv),
                       hysteresis_n=float(max(hyst, 0.0)), slack_deg=slack, preload_std_n=preload_std,
                       residual_std_n=math.sqrt(sigma2), covariance=tuple(float(c) for c in cov.ravel()),
                       max_angle_deg=float(a.max()), source=data.source)


def springs_table(curve: SpringCurve, provenance: str) -> str:
    """The rig file's ``[springs]`` table for a fitted curve (read back by ``labctl.physics.rig_config``)."""
    from labctl.calibration.rigfile import toml_value

    lines = [f"[springs]  # knob angle -> load per roller, fitted by labctl springs fit from {provenance}"]
    for key in ("preload_n", *PARAMETERS, "preload_std_n", "residual_std_n"):
        lines.append(f"{key} = {toml_value(float(getattr(curve, key)))}")
    lines.append(f"covariance = {toml_value([float(c) for c in curve.covariance])}  # 4x4 over {', '.join(PARAMETERS)}")
    lines.append(f"max_angle_deg = {toml_value(float(curve.max_angle_deg))}")
    lines.append(f"source = {toml_value(provenance)}")
    return "\n".join(lines) + "\n"


def rig_text_with_springs(rig_text: str, source: str, curve: SpringCurve, provenance: str) -> str:
    """The rig file's text with its ``[springs]`` table replaced (or added); checked by reading it back."""
    from labctl.calibration.rigfile import _HEADER
    from labctl.physics.rig_config import rig_from_text

    out, skipping = [], False
    for line in rig_text.splitlines():
        header = _HEADER.match(line)
        if header:
            skipping = header.group(1) == "springs"
        if not skipping:
            out.append(line)
    text = "\n".join(out).rstrip("\n") + "\n\n" + springs_table(curve, provenance)
    back = rig_from_text(text, source).springs
    if back is None or not math.isclose(back.rate_n_per_deg, curve.rate_n_per_deg, rel_tol=1e-12):
        raise InputError(f"{source}: the [springs] table did not read back")
    return text
