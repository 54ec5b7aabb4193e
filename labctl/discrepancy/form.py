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
from numpy.typing import ArrayLike

from labctl.discrepancy.data import Dataset
from labctl.discrepancy.measurement import MEASUREMENT
from labctl.discrepancy.model import Fit, predict_ln
from labctl.discrepancy.noise import NoiseFloor

TAU_GRID = np.geomspace(3e-4, 0.3, 16)
"""σ of the form discrepancy's coefficients (in ln k): log-uniform prior over these values."""
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


def form_basis(data: Dataset) -> np.ndarray:
    """Legendre P_0..P_FORM_DEGREE of ln(load per length) per roller case (columns zero outside the case)."""
    x = np.log(data.load_per_length_n_per_m)
    cols = []
    for sl in data.case_slices():
        u = x[sl]
        span = float(np.ptp(u))
        u = (u - u.min()) / span * 2 - 1 if span > 0 else np.zeros_like(u)
        degree = min(FORM_DEGREE, max(0, np.unique(np.round(u, 6)).size - 1))
        for j in range(degree + 1):
            col = np.zeros(x.size)
            col[sl] = np.polynomial.legendre.legval(u, [0] * j + [1])
            cols.append(col)
    return np.stack(cols, axis=1)


@dataclass(frozen=True)
class FormPrior:
    """The whitened form basis's SVD: what integrating the discrepancy out needs."""

    u: np.ndarray
    s2: np.ndarray
    a: np.ndarray | None = None
    """The whitened basis itself (for the joint marginal with a term's bend columns)."""
    cases: tuple[tuple[slice, np.ndarray, np.ndarray], ...] = ()
    """Per roller case: its rows, and the SVD (u, s²) of its block of the whitened basis (``case_log_marginals``)."""

    @classmethod
    def of(cls, data: Dataset, noise: NoiseFloor, sigma: np.ndarray) -> FormPrior:
        a = noise.whiten(data, form_basis(data), sigma)
        # whitening stays within a seating, so the basis is block-diagonal by case: its SVD is the cases' SVDs
        blocks = [(sl, *np.linalg.svd(a[sl][:, np.any(a[sl] != 0.0, axis=0)], full_matrices=False)[:2])
                  for sl in data.case_slices()]
        floor = 1e-9 * max(float(s.max()) for _, _, s in blocks)
        cases = tuple((sl, u[:, s > floor], s[s > floor] ** 2) for sl, u, s in blocks)
        u = np.zeros((a.shape[0], sum(uc.shape[1] for _, uc, _ in cases)))
        col = 0
        for sl, uc, _ in cases:
            u[sl, col:col + uc.shape[1]] = uc
            col += uc.shape[1]
        return cls(u, np.concatenate([s2 for _, _, s2 in cases]), a, cases)

    def bend_mean(self, e: np.ndarray, bend: np.ndarray, inflation: float, tau: float) -> np.ndarray:
        """The posterior mean of the bend part Bγ at one T and τ, the discrepancy integrated out with it."""
        assert self.a is not None
        a = np.column_stack([self.a, bend])
        d = _joint_prior(np.array([tau**2]), self.a.shape[1], a.shape[1])[0]
        coef = np.linalg.solve(a.T @ a / inflation + np.diag(1.0 / d), a.T @ e / inflation)
        return bend @ coef[self.a.shape[1]:]

    def case_log_marginals(self, e: np.ndarray, inflation: float, tau: float) -> list[float]:
        """Each roller case's part of log N(e; 0, T·I + τ²AA') at one T and τ (the basis is block-diagonal by case,
        so the parts sum to the whole; a term's bend columns, shared by the cases, are left out)."""
        return [float(_log_marginal(float(e[sl] @ e[sl]), (u.T @ e[sl]) ** 2, s2, tau**2, inflation))
                for sl, u, s2 in self.cases]

    def log_marginal(self, e: np.ndarray, bend: np.ndarray | None = None, inflation: float = 1.0
                     ) -> tuple[float, float]:
        """log ∫ N(e; Aβ + Bγ, T·I) N(β; 0, τ²) N(γ; 0, BEND_SIGMA²) dβ dγ averaged over TAU_GRID (constants the
        same for every candidate dropped), and the τ it favours. ``bend``: whitened bend columns B of the
        candidate's terms (or none); ``inflation``: T."""
        return self.log_marginals(e, bend, (inflation,))[0]

    def log_marginals(self, e: np.ndarray, bend: np.ndarray | None, inflations: Sequence[float]
                      ) -> list[tuple[float, float]]:
        """``log_marginal`` at each inflation T, the products with the data formed once."""
        t = np.asarray(inflations, dtype=float)[:, None]  # one row per T, one column per τ
        tau2 = np.asarray(TAU_GRID, dtype=float) ** 2
        if bend is None or bend.shape[1] == 0 or self.a is None:
            v = _log_marginal(float(e @ e), (self.u.T @ e) ** 2, self.s2, tau2[None, :], t)
        else:
            a = np.column_stack([self.a, bend])
            ata, ate = a.T @ a, a.T @ e
            m1, n = self.a.shape[1], a.shape[1]
            # every (T, τ) in one batched factorisation
            d = _joint_prior(tau2, m1, n)
            m = np.repeat(ata[None, None] / t[:, :, None, None], len(TAU_GRID), axis=1)
            m[..., np.arange(n), np.arange(n)] += 1.0 / d[None]
            chol = np.linalg.cholesky(m)
            rhs = np.broadcast_to((ate[None, None, :] / t[:, :, None])[..., None], (*m.shape[:3], 1))
            z = np.linalg.solve(chol, rhs)[..., 0]
            logdet = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=2, axis2=3)), axis=2) + np.sum(np.log(d), axis=1)
            v = -0.5 * (float(e @ e) / t - np.sum(z**2, axis=2)) - 0.5 * logdet
        top = np.max(v, axis=1)
        mean = top + np.log(np.mean(np.exp(v - top[:, None]), axis=1))  # log of the mean over τ, without overflow
        return [(float(x), float(TAU_GRID[int(i)])) for x, i in zip(mean, np.argmax(v, axis=1), strict=True)]

    def transform(self, tau: float):  # noqa: ANN201
        """e → (I + τ²AA')^(-1/2)·e: least squares on it is the fit at that discrepancy scale."""
        d = 1.0 - 1.0 / np.sqrt(1.0 + tau**2 * self.s2)
        u = self.u
        return lambda e: e - u @ (d * (u.T @ e))

    def smooth(self, e: np.ndarray, tau: float) -> np.ndarray:
        """The posterior mean of the discrepancy (whitened units) at scale τ."""
        g = tau**2 * self.s2
        return self.u @ (g / (1 + g) * (self.u.T @ e))



def _log_marginal(ee: float, proj2: np.ndarray, s2: np.ndarray, tau2: ArrayLike, inflation: ArrayLike
                  ) -> np.ndarray:
    """log N(e; 0, T·I + τ²·UΣ²U') less its constant, from e'e, (U'e)² and Σ² (one entry per singular value); τ²
    and T may be arrays that broadcast against each other (the result has their shape)."""
    tau2, t = np.asarray(tau2, dtype=float), np.asarray(inflation, dtype=float)
    g = tau2[..., None] * s2 / t[..., None]
    return -0.5 * (ee - np.sum(g / (1 + g) * proj2, axis=-1)) / t - 0.5 * np.sum(np.log1p(g), axis=-1)


def _joint_prior(tau2: np.ndarray, m1: int, n: int) -> np.ndarray:
    """The prior variances of the joint coefficients (the discrepancy's ``m1``, then a term's bend columns up to
    ``n``), one row per τ²."""
    d = np.empty((tau2.size, n))
    d[:, :m1] = tau2[:, None]
    d[:, m1:] = BEND_SIGMA**2
    return d
