"""The planning criterion: expected information a set of new points gives about the models in play.

For one specimen, every model k in play predicts ln k at the specimen's reachable loads: mean μ_k and, from its
parameter covariance C_k (``labctl.planning.rivals``), prediction covariance V_k = J_k C_k J_kᵀ. New points of
one mounting have noise Σ = diag(σ²) + τ²·11ᵀ (the point noise σ(F/L_we) and seating σ τ of the workflow's
noise model). Under model k the new points are then distributed N(μ_k, S_k), S_k = Σ + V_k.

- Discrimination (Box & Hill 1967): Σ_{i<j} w_i w_j (KL_ij + KL_ji), KL_ij the Kullback-Leibler divergence of
  N(μ_i, S_i) from N(μ_j, S_j), w the models' BIC weights. 2·KL_ij is the expected shift of the BIC difference
  in favour of i when i is true.
- Parameters (Bayesian D-optimality): Σ_k w_k · ½ ln(det C_k,T / det C'_k,T), C'_k the covariance after the
  new points (C'_k = C_k − C_k J_kᵀ S_k⁻¹ J_k C_k) and T the rows of model k's term parameters (Tripp's
  depth, a nuisance parameter, left out).

The score of a set of loads is the sum of both (nats). Loads are chosen greedily, one at a time, from the
specimen's reachable loads up to the step budget: each at most once, or, with ``repeat``, again whenever a
repeat raises the score most. A repeated load is another step at that knob angle in the same seating: new
blows and a new identification (independent point noise σ), the same seating offset τ, as the noise model
has it; two points at one load are therefore correlated by τ² only, not by σ² + τ² (``set_noise``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from labctl.planning.rivals import Rival


@dataclass(frozen=True)
class ModelAt:
    """One model's prediction at a specimen's reachable loads."""

    rival: Rival
    weight: float
    mu: np.ndarray
    jac: np.ndarray
    term_rows: np.ndarray
    """Indices of the term parameters (the depth left out) in the parameter vector."""

    @property
    def cov_full(self) -> np.ndarray:
        assert self.rival.covariance is not None
        return self.jac @ self.rival.covariance @ self.jac.T


@dataclass(frozen=True)
class Score:
    total: np.ndarray
    discrimination: np.ndarray
    parameters: np.ndarray
    pair_terms: dict[tuple[int, int], np.ndarray]
    """w_i w_j (KL_ij + KL_ji) per model pair."""
    kl: dict[tuple[int, int], np.ndarray]
    """KL_ij per ordered pair (i true)."""
    param_terms: dict[int, np.ndarray]
    """w_k · ½ ln(det C_k,T / det C'_k,T) per model with term parameters."""


def _logdet(a: np.ndarray) -> np.ndarray:
    sign, val = np.linalg.slogdet(a)
    return np.where(sign > 0, val, -np.inf)


def set_noise(noise: np.ndarray, sets: np.ndarray, point_var: np.ndarray | None = None) -> np.ndarray:
    """Noise covariance of each set of load indices (n × m × m): ``noise`` between points at distinct loads; two
    points at the same load share it less their independent point variance ``point_var`` (default: all of the
    diagonal, i.e. ``noise`` is diagonal)."""
    rows, cols = sets[:, :, None], sets[:, None, :]
    var = np.diag(noise) if point_var is None else point_var
    repeats = (rows == cols) & ~np.eye(sets.shape[1], dtype=bool)
    return np.where(repeats, noise[rows, cols] - var[rows], noise[rows, cols])


def score_sets(models: list[ModelAt], noise: np.ndarray, sets: np.ndarray, point_var: np.ndarray | None = None
               ) -> Score:
    """The criterion for each candidate set of load indices (rows of ``sets``, shape n × m; a load may repeat,
    see ``set_noise``)."""
    rows, cols = sets[:, :, None], sets[:, None, :]
    noise_sets = set_noise(noise, sets, point_var)
    s = [noise_sets + m.cov_full[rows, cols] for m in models]
    s_inv = [np.linalg.inv(x) for x in s]
    mus = [m.mu[sets] for m in models]
    m_dim = sets.shape[1]
    n = sets.shape[0]
    disc = np.zeros(n)
    pair_terms: dict[tuple[int, int], np.ndarray] = {}
    kl: dict[tuple[int, int], np.ndarray] = {}
    logdets = [_logdet(x) for x in s]
    for i in range(len(models)):
        for j in range(len(models)):
            if i == j:
                continue
            d = mus[i] - mus[j]
            quad = np.einsum("na,nab,nb->n", d, s_inv[j], d)
            trace = np.einsum("nab,nba->n", s_inv[j], s[i])
            kl[(i, j)] = 0.5 * (trace - m_dim + quad + logdets[j] - logdets[i])
    for i in range(len(models)):
        for j in range(i + 1, len(models)):
            term = models[i].weight * models[j].weight * (kl[(i, j)] + kl[(j, i)])
            pair_terms[(i, j)] = term
            disc = disc + term
    params = np.zeros(n)
    param_terms: dict[int, np.ndarray] = {}
    for k, (m, si) in enumerate(zip(models, s_inv, strict=True)):
        t = m.term_rows
        if t.size == 0 or m.weight <= 0:
            continue
        c = m.rival.covariance
        assert c is not None
        jc = m.jac[sets] @ c  # n × m × p
        c_new = c[None] - np.einsum("nap,nab,nbq->npq", jc, si, jc)
        before = _logdet(c[np.ix_(t, t)][None])
        after = _logdet(c_new[:, t[:, None], t[None, :]])
        param_terms[k] = m.weight * 0.5 * (before - after)
        params = params + param_terms[k]
    return Score(disc + params, disc, params, pair_terms, kl, param_terms)


def greedy_loads(models: list[ModelAt], noise: np.ndarray, budget: int, repeat: bool = False,
                 point_var: np.ndarray | None = None) -> tuple[np.ndarray, Score]:
    """Indices of up to ``budget`` loads chosen one at a time for the largest score (each load at most once,
    or as often as it is the best next choice with ``repeat``; ``point_var`` as in ``set_noise``), and the
    final score."""
    g = noise.shape[0]
    chosen: list[int] = []
    best: Score | None = None
    for _ in range(budget if repeat else min(budget, g)):
        free = np.array([i for i in range(g) if repeat or i not in chosen])
        sets = np.column_stack([np.tile(chosen, (free.size, 1)).astype(int), free]) if chosen else free[:, None]
        sc = score_sets(models, noise, sets, point_var)
        k = int(np.nanargmax(sc.total))
        chosen.append(int(free[k]))
        best = _pick(sc, k)
    assert best is not None
    order = np.argsort(chosen)
    return np.array(chosen)[order], best


def _pick(sc: Score, k: int) -> Score:
    one = slice(k, k + 1)
    return Score(sc.total[one], sc.discrimination[one], sc.parameters[one],
                 {key: v[one] for key, v in sc.pair_terms.items()}, {key: v[one] for key, v in sc.kl.items()},
                 {key: v[one] for key, v in sc.param_terms.items()})
