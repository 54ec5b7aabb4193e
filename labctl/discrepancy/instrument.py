"""An instrument error is one value for every roller: the consistency test of a rig-level term.

A load cell offset or gain, or a wrong modulus, is a property of the instrument or the catalogue, and the rig's own
stiffness (``setup_compliance``: K_setup) a property of the rig, so every roller type measured with it shows the
same value. A term that only mends the form of a physical law (a load offset that shifts a tilt law's closing, a
"rig compliance" standing in for a compliant layer under each roller) wants a different value for each roller
type, because the form error differs with the roller's length and diameter. Each measurement-side parameter of a
fitted explanation is refitted on each roller geometry alone (every other parameter held at the joint fit) and the
values are compared: Cochran's Q = Σ w_g·(θ_g − θ̄)², w_g = 1/σ_g², against χ² with G − 1 degrees of freedom at
level ``CONSISTENCY_LEVEL``. The rig's compliance may depend on load, so it is compared at the loads the roller
types share, against the spread between seatings of one type (``_same_curve``). A term whose joint fit sits at an
end of its range is no instrument error either: it is being stretched to another shape."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.special import chdtrc, fdtrc

from labctl.discrepancy.data import Dataset
from labctl.discrepancy.lsq import forward_steps
from labctl.discrepancy.measurement import MEASUREMENT
from labctl.discrepancy.model import Fit, depth_column, residuals_at
from labctl.discrepancy.noise import NoiseFloor
from labctl.physics.effects import EFFECTS

CONSISTENCY_LEVEL = 0.01
"""A rig-level term whose per-roller-type values differ at this level is not an instrument or rig error."""
MIN_GEOMETRIES = 3
"""Roller geometries needed to compare (with fewer, the test is not made and nothing is ruled out)."""
PIN_WINDOW = 0.01
"""How near an end of its range (in the [0, 1] scale) a joint-fit value is asked whether the data pull it beyond."""
_STEP = 1e-6
"""Forward-difference step (in the parameter's [0, 1] scale) for the Gauss–Newton steps and each value's standard
error, taken as the fits take theirs (``forward_steps``: turned back at the range's upper end)."""
_UNIT = (np.zeros(1), np.ones(1))
RIG_CURVE_DEGREE = 2
"""Degree in ln F of the compliance curve every roller shares when a rig property is compared across roller types."""
NEWTON_STEPS = 8
NEWTON_TOLERANCE = 1e-7


def rig_level(term: str) -> bool:
    """One value for every roller measured on the rig: a measurement-side term, or a physical effect of the rig
    itself (``RIG_LEVEL``)."""
    return term in MEASUREMENT or bool(getattr(EFFECTS.get(term), "RIG_LEVEL", False))


@dataclass(frozen=True)
class InstrumentCheck:
    """One rig-level parameter compared across roller geometries, and whether the values agree."""

    term: str
    parameter: str
    values: tuple[float, ...]
    """Per roller geometry, in the parameter's SI unit."""
    sigmas: tuple[float, ...]
    q: float
    df: int
    p: float
    at_bound: bool
    """The joint fit's value sits at an end of the term's range: the data want more than an instrument error of
    this kind plausibly is (the range is the term's prior support), so the term is bending to fit another shape."""
    df_within: int = 0
    """0: ``q`` is Cochran's Q against χ²(``df``); else ``q`` is an F ratio, the roller types' spread against the
    spread between seatings of one roller type, on (``df``, ``df_within``) degrees of freedom."""

    @property
    def passed(self) -> bool:
        """The term can be an instrument error: one value for every roller, inside its range."""
        return self.p >= CONSISTENCY_LEVEL and not self.at_bound

    def describe(self) -> str:
        """Why the term can or cannot be an instrument error, in words."""
        if self.at_bound:
            return (f"{self.term} pinned at the end of its range: an error larger than the range allows, or the term "
                    "stretched to another shape")
        p = "p < 1e-10" if self.p < 1e-10 else f"p {self.p:.2g}"
        verb = "agrees across" if self.p >= CONSISTENCY_LEVEL else "differs by"
        test = (f"F {self.q:.1f} on {self.df}, {self.df_within} df against the seatings of one roller type"
                if self.df_within else f"Cochran's Q {self.q:.1f}, {self.df} df")
        return f"{self.term} {verb} roller type ({test}, {p} at level {CONSISTENCY_LEVEL:g})"

    def to_dict(self) -> dict[str, Any]:
        return {"term": self.term, "parameter": self.parameter, "values": list(self.values),
                "sigmas": list(self.sigmas), "q": self.q, "df": self.df, "p": self.p, "at_bound": self.at_bound,
                "df_within": self.df_within, "level": CONSISTENCY_LEVEL, "passed": self.passed,
                "description": self.describe()}


def _whitened(sub: Dataset, fit: Fit, j: int, noise: NoiseFloor) -> Callable[[float], np.ndarray]:
    """The whitened residuals on ``sub`` as a function of parameter ``j`` of ``fit`` (its [0, 1] scale), the other
    parameters held at the joint fit."""
    spec, sigma = fit.spec, noise.sigma_at(sub)

    def white(u: float) -> np.ndarray:
        x = fit.x.copy()
        x[j] = u
        return noise.whiten(sub, residuals_at(sub, spec, x, sub.ln_stiffness), sigma)

    return white


def _newton(white: Callable[[float], np.ndarray], u: float) -> tuple[float, float]:
    """One Gauss–Newton step from ``u``, unbounded: where it lands, and the Fisher information at ``u`` (0: the
    residuals do not depend on the parameter, and it stays)."""
    h = float(forward_steps(np.array([u]), *_UNIT, _STEP)[0])
    r = white(u)
    jac = (white(u + h) - r) / h
    info = float(jac @ jac)
    return (u - float(jac @ r) / info if info > 0 else u), info


def _refit(sub: Dataset, fit: Fit, j: int, noise: NoiseFloor) -> tuple[float, float]:
    """Parameter ``j`` of ``fit`` (in its [0, 1] scale) refitted on ``sub`` alone (Gauss–Newton from the joint
    fit's value, held in [0, 1]), and its Fisher information there."""
    white = _whitened(sub, fit, j, noise)
    u = float(fit.x[j])
    for _ in range(NEWTON_STEPS):
        target, info = _newton(white, u)
        if info <= 0:
            return u, 0.0
        u_next = min(1.0, max(0.0, target))
        done = abs(u_next - u) < NEWTON_TOLERANCE
        u = u_next
        if done:
            break
    return u, _newton(white, u)[1]


def _pinned(data: Dataset, fit: Fit, j: int, noise: NoiseFloor) -> bool:
    """Parameter ``j`` of the joint fit sits at an end of its range because the data pull it beyond: within
    ``PIN_WINDOW`` of the end, a Gauss–Newton step (the other parameters held) lands outside the range — the bound
    is active. Where the optimiser stopped, 1e-9 or 1e-5 from the end, does not decide it."""
    u = float(fit.x[j])
    if min(u, 1.0 - u) > PIN_WINDOW:
        return False
    target, info = _newton(_whitened(data, fit, j, noise), u)
    return info > 0 and not 0.0 <= target <= 1.0


def _same_curve(data: Dataset, fit: Fit, noise: NoiseFloor, term: str, at_bound: bool) -> InstrumentCheck:
    """A physical property of the rig (its own compliance), compared across roller types at the loads they share.

    The rig's compliance may depend on load (a joint that stiffens), so a constant stand-in fitted to each roller
    type over its own load range would differ for that reason alone. The joint fit's residuals, read as an extra
    compliance Δc (Δ ln k = k·Δc), are fitted by one curve in ln F that every roller shares (degree
    ``RIG_CURVE_DEGREE``; Tripp's depth refitted with it), then with a level per roller geometry, then per
    seating. The levels' gain over the seatings' gain within a type is an F ratio on G − 1 and S − G degrees of
    freedom (S seatings): the seatings' own scatter, which the noise model may underrate, is the yardstick (a χ²
    against the noise model alone once ruled out a true constant K_setup error). Without repetitions the yardstick
    is the noise model (χ² on G − 1). The values are the levels (m/N, about their weighted mean) with their
    marginal σ: the depth trades off with one direction of them, so a single level is loosely known and the test
    is the ratio. A rig that drifts over the campaign differs by roller type when the types were measured one
    after another, and fails: the data cannot tell it from a property of each roller's seat."""
    k = np.exp(fit.residuals + data.ln_stiffness)  # the joint fit's stiffness at every point
    x = np.log(data.load_n)
    u = (x - x.mean()) / max(float(x.std()), 1e-12)
    depth = depth_column(fit, data)
    nuisance = [k * u**d for d in range(1, RIG_CURVE_DEGREE + 1)] + ([] if depth is None else [depth])
    sigma = noise.sigma_at(data)
    z = noise.whiten(data, fit.residuals, sigma)

    def solve(labels: np.ndarray | None) -> tuple[np.ndarray, float, int, np.ndarray]:
        """Least squares of the whitened residuals on a compliance level per label (one level: None) and the
        nuisance columns, on unit columns (a compliance column is ~1e9 × the depth's): coefficients, χ², rank and
        covariance."""
        levels = [k] if labels is None else [k * (labels == g) for g in np.unique(labels)]
        a = noise.whiten(data, np.column_stack(levels + nuisance), sigma)
        norms = np.linalg.norm(a, axis=0)
        unit = a / norms
        coef, _, rank, _ = np.linalg.lstsq(unit, z, rcond=None)
        e = z - unit @ coef
        return coef / norms, float(e @ e), int(rank), np.linalg.pinv(unit.T @ unit) / np.outer(norms, norms)

    _, rss0, rank0, _ = solve(None)
    coef, rss1, rank1, cov = solve(data.roller_index())
    _, rss2, rank2, _ = solve(data.run_ids())
    g = len(data.roller_keys())
    w = 1.0 / np.diag(cov)[:g]
    about_mean = np.eye(g) - np.outer(np.ones(g), w / w.sum())
    v = about_mean @ coef[:g]
    sd = np.sqrt(np.maximum(np.diag(about_mean @ cov[:g, :g] @ about_mean.T), 0.0))
    between, df = max(0.0, rss0 - rss1), max(0, rank1 - rank0)
    within, df_within = max(0.0, rss1 - rss2), max(0, rank2 - rank1)
    if df_within == 0 or within <= 0:  # one seating per roller type: the noise model is all there is to judge by
        q, df_within, p = between, 0, float(chdtrc(df, between)) if df else 1.0
    else:
        q = (between / max(df, 1)) / (within / df_within)
        p = float(fdtrc(df, df_within, q)) if df else 1.0
    return InstrumentCheck(term, "compliance_m_per_n", tuple(float(t) for t in v), tuple(float(t) for t in sd), q,
                           df, p, at_bound, df_within)


def _per_geometry(data: Dataset, fit: Fit, noise: NoiseFloor, term: str, parameter: str, j: int, lo: float,
                  hi: float, at_bound: bool) -> InstrumentCheck:
    """A measurement-side parameter refitted on each roller geometry alone (``_refit``), compared by Cochran's Q."""
    refits = [_refit(data.subset(idx), fit, j, noise) for idx in data.roller_groups()]
    v = np.array([lo + u * (hi - lo) for u, _ in refits])
    w = np.array([info / (hi - lo) ** 2 for _, info in refits])
    informative = int(np.count_nonzero(w))
    mean = float(np.sum(w * v) / np.sum(w)) if informative else 0.0
    q = float(np.sum(w * (v - mean) ** 2))
    p = float(chdtrc(informative - 1, q)) if informative >= 2 else 1.0
    sigmas = tuple(float(1.0 / np.sqrt(x)) if x > 0 else float("inf") for x in w)
    return InstrumentCheck(term, parameter, tuple(float(x) for x in v), sigmas, q, max(0, informative - 1), p,
                           at_bound)


def check_instrument(data: Dataset, fit: Fit, noise: NoiseFloor) -> list[InstrumentCheck]:
    """Every rig-level parameter (``rig_level``) of ``fit`` compared across roller geometries: a measurement-side
    one refitted per geometry (``_per_geometry``), the rig's own compliance by ``_same_curve``; empty with fewer than
    ``MIN_GEOMETRIES`` geometries or no rig-level term."""
    spec = fit.spec
    if len(data.roller_keys()) < MIN_GEOMETRIES:
        return []
    out = []
    for slot, (term, parameter, lo, hi) in enumerate(spec.slots()):
        if not rig_level(term):
            continue
        j = int(spec.fits_depth) + slot
        at_bound = _pinned(data, fit, j, noise)
        out.append(_per_geometry(data, fit, noise, term, parameter, j, lo, hi, at_bound) if term in MEASUREMENT
                   else _same_curve(data, fit, noise, term, at_bound))
    return out
