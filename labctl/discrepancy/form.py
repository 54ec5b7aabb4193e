"""The form of every explanation is uncertain: a smooth discrepancy per roller case, and each term bent with load.

``FormPrior``: the discrepancy δ_c(ln p) = Σ_j β_cj·P_j(u) per roller case (Legendre P_0..P_2 of ln p scaled to
[−1, 1] over the case's loads), β ~ N(0, τ²), τ log-uniform on ``TAU_GRID``, integrated out exactly (linear
Gaussian). ``contribution``: a term's part of the model (ln k with it minus without it), which the posterior
(``labctl.discrepancy.posterior``) bends with load: a real effect whose law differs from the library's term is
still that term, bent.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from labctl.discrepancy.data import Dataset
from labctl.discrepancy.measurement import MEASUREMENT
from labctl.discrepancy.model import Fit, predict_ln
from labctl.discrepancy.noise import NoiseFloor

TAU_GRID = np.geomspace(3e-4, 0.3, 16)
"""σ of the form discrepancy's level coefficients (in ln k): log-uniform prior over these values."""
SHAPE_RATIOS = (1.0, 0.3, 0.1, 0.03)
"""σ of the slope and bend coefficients over the level's (uniform prior over these values): a discrepancy may be
mostly a level per roller case (a catalogue geometry or a law's scaling with it slightly off) without paying for a
slope and a bend in every case."""
FORM_DEGREE = 2
"""Legendre degree of each roller case's smooth discrepancy (0: a level, 1: a slope, 2: a bend with ln p)."""
BEND_SIGMA = 0.5
"""Prior σ of each term's bend coefficients: its contribution d_t becomes d_t·(1 + b₁·u + b₂·u²), u = ln(p/p̄)
over all roller cases (the same law for every roller: an approximate form that still generalises)."""


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


def form_basis(data: Dataset) -> tuple[np.ndarray, np.ndarray]:
    """Legendre P_0..P_FORM_DEGREE of ln(load per length) per roller case (columns zero outside the case), and
    each column's degree."""
    x = np.log(data.load_per_length_n_per_m)
    cols, degrees = [], []
    for sl in data.case_slices():
        u = x[sl]
        span = float(np.ptp(u))
        u = (u - u.min()) / span * 2 - 1 if span > 0 else np.zeros_like(u)
        degree = min(FORM_DEGREE, max(0, np.unique(np.round(u, 6)).size - 1))
        for j in range(degree + 1):
            col = np.zeros(x.size)
            col[sl] = np.polynomial.legendre.legval(u, [0] * j + [1])
            cols.append(col)
            degrees.append(j)
    return np.stack(cols, axis=1), np.array(degrees)


Scale = tuple[float, float]
"""A discrepancy's scale: the level coefficients' σ τ, and the slope and bend coefficients' ratio to it."""


@dataclass(frozen=True)
class WhitenedBasis:
    """The whitened form basis at one shape ratio (its slope and bend columns scaled by it) and its SVD."""

    ratio: float
    u: np.ndarray
    s2: np.ndarray
    a: np.ndarray
    """The whitened, scaled basis itself (for the joint marginal with a term's bend columns)."""

    @classmethod
    def of(cls, a: np.ndarray, ratio: float = 1.0) -> WhitenedBasis:
        u, s, _ = np.linalg.svd(a, full_matrices=False)
        keep = s > 1e-9 * s.max()
        return cls(ratio, u[:, keep], s[keep] ** 2, a)

    def log_marginals(self, e: np.ndarray, bend: np.ndarray | None, t: np.ndarray) -> np.ndarray:
        """log N(e; 0, T·I + τ²AA' + BΣB') at each inflation T (rows) and each τ of ``TAU_GRID`` (columns)."""
        tau2 = np.asarray(TAU_GRID, dtype=float) ** 2
        ee = float(e @ e) / t
        if bend is None or bend.shape[1] == 0:
            proj2 = (self.u.T @ e) ** 2
            g = tau2[None, :, None] * self.s2 / t[:, :, None]  # T × τ × singular value
            return -0.5 * (ee - np.sum(g / (1 + g) * proj2, axis=2) / t) - 0.5 * np.sum(np.log1p(g), axis=2)
        a = np.column_stack([self.a, bend])
        ata, ate = a.T @ a, a.T @ e
        m1, n = self.a.shape[1], a.shape[1]
        # every (T, τ) in one batched factorisation
        d = np.empty((len(TAU_GRID), n))
        d[:, :m1] = tau2[:, None]
        d[:, m1:] = BEND_SIGMA**2
        m = np.repeat(ata[None, None] / t[:, :, None, None], len(TAU_GRID), axis=1)
        m[..., np.arange(n), np.arange(n)] += 1.0 / d[None]
        chol = np.linalg.cholesky(m)
        rhs = np.broadcast_to((ate[None, None, :] / t[:, :, None])[..., None], (*m.shape[:3], 1))
        z = np.linalg.solve(chol, rhs)[..., 0]
        logdet = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=2, axis2=3)), axis=2) + np.sum(np.log(d), axis=1)
        return -0.5 * (ee - np.sum(z**2, axis=2)) - 0.5 * logdet


@dataclass(frozen=True)
class FormPrior:
    """The discrepancy's prior: one whitened basis per shape ratio (``SHAPE_RATIOS``), τ on ``TAU_GRID``."""

    bases: tuple[WhitenedBasis, ...]

    @classmethod
    def of(cls, data: Dataset, noise: NoiseFloor, sigma: np.ndarray,
           ratios: Sequence[float] = SHAPE_RATIOS) -> FormPrior:
        basis, degree = form_basis(data)
        a = noise.whiten(data, basis, sigma)
        return cls(tuple(WhitenedBasis.of(a * np.where(degree > 0, r, 1.0), r) for r in ratios))

    def log_marginal(self, e: np.ndarray, bend: np.ndarray | None = None, inflation: float = 1.0
                     ) -> tuple[float, Scale]:
        """log ∫ N(e; Aβ + Bγ, T·I) N(β; 0, τ²·diag(1, r², r²)) N(γ; 0, BEND_SIGMA²) dβ dγ averaged over τ on
        TAU_GRID and r on SHAPE_RATIOS (constants the same for every candidate dropped), and the (τ, r) it favours.
        ``bend``: whitened bend columns B of the candidate's terms (or none); ``inflation``: T."""
        return self.log_marginals(e, bend, (inflation,))[0]

    def log_marginals(self, e: np.ndarray, bend: np.ndarray | None, inflations: Sequence[float]
                      ) -> list[tuple[float, Scale]]:
        """``log_marginal`` at each inflation T, the products with the data formed once."""
        t = np.asarray(inflations, dtype=float)[:, None]
        v = np.stack([b.log_marginals(e, bend, t) for b in self.bases], axis=1)  # T × ratio × τ
        flat = v.reshape(v.shape[0], -1)
        top = np.max(flat, axis=1)
        mean = top + np.log(np.mean(np.exp(flat - top[:, None]), axis=1))  # log of the mean, without overflow
        at = [np.unravel_index(int(i), v.shape[1:]) for i in np.argmax(flat, axis=1)]
        return [(float(x), (float(TAU_GRID[j]), self.bases[i].ratio)) for x, (i, j) in zip(mean, at, strict=True)]

    def _basis(self, scale: Scale) -> WhitenedBasis:
        return next(b for b in self.bases if b.ratio == scale[1])

    def transform(self, scale: Scale):  # noqa: ANN201
        """e → (I + AΣA')^(-1/2)·e: least squares on it is the fit at that discrepancy scale."""
        b = self._basis(scale)
        d = 1.0 - 1.0 / np.sqrt(1.0 + scale[0] ** 2 * b.s2)
        u = b.u
        return lambda e: e - u @ (d * (u.T @ e))

    def smooth(self, e: np.ndarray, scale: Scale) -> np.ndarray:
        """The posterior mean of the discrepancy (whitened units) at that scale."""
        b = self._basis(scale)
        g = scale[0] ** 2 * b.s2
        return b.u @ (g / (1 + g) * (b.u.T @ e))
