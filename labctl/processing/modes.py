"""Multi-channel parametric fit of the rig's contact modes (common poles, real modal constants).

Model, per channel c, evaluated at ``s = iω + a`` (``a`` = the exponential window's rate, so the window's
added damping is removed exactly)::

    H_c(s) = Σ_r C_rc · s² / (s² + 2 ζ_r Ω_r s + Ω_r²)  +  R0_c + R2_c · (s/Ω_ref)²

with real modal constants C (proportional damping) and complex residual terms for the modes outside the
band (rigid-body support modes below, flexible modes above). Poles start from a multi-channel least-squares
complex-frequency estimate (common denominator, Sanathanan–Koerner reweighted) and are refined by variable
projection: the linear constants are eliminated, Levenberg–Marquardt moves the frequencies and damping
ratios only, and their covariance (the Schur complement) gives the uncertainties.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

TWO_PI = 2.0 * math.pi
LOG_ZETA_MIN = math.log(1e-6)
RESIDUAL_POWERS = (-2, 0, 2, 4)  # complex residual terms (s/Ω_ref)^p for the modes outside the band
GN_TOLERANCE = 1e-3  # convergence: the remaining decrease the Gauss–Newton step promises, in noise variances


@dataclass(frozen=True)
class ModalFit:
    """Fitted poles with 1-σ uncertainties and the modal constants per channel."""

    frequencies_hz: np.ndarray  # (M,) undamped natural frequencies Ω/2π
    damping_ratios: np.ndarray
    frequency_std_hz: np.ndarray
    damping_std: np.ndarray
    constants: np.ndarray  # (M, n_ch) real modal constants (m/s² per N)
    cost: float  # weighted sum of squared residuals
    sigma2: float  # residual variance per real datum after weighting
    n_data: int
    band_hz: tuple[float, float]
    converged: bool
    channel_rms: np.ndarray  # (n_ch,) residual RMS per channel, in the FRF's units
    significance: np.ndarray  # (M,) rise of the cost (in σ² units) if the mode's constants were dropped
    force_covariance: np.ndarray | None = None  # (2M, 2M) over (f_r, ln ζ_r): the force noise's share
    constants_std: np.ndarray | None = None  # (M, n_ch) 1-σ of the modal constants (response noise)


def _stack(z: np.ndarray) -> np.ndarray:
    """Complex (n, ...) → real (2n, ...) as [Re; Im]."""
    return np.concatenate([z.real, z.imag], axis=0)


class _Problem:
    """Variable-projection residual and Gauss–Newton terms for M modes on one band, all channels at once.

    The residual terms do not depend on the poles, so they are projected out of the data once; each step
    then only handles the M mode columns. With the Kaufman Jacobian J_k = -vec(P⊥ ∂B/∂θ_k ⊗ c_r), JᵀJ
    and Jᵀr reduce to small products: the (n_lines·n_channels × 2M) Jacobian is never formed.
    """

    def __init__(self, freqs_hz: np.ndarray, h: np.ndarray, decay_rate: float, weights: np.ndarray) -> None:
        self.s = TWO_PI * 1j * freqs_hz + decay_rate
        self.s2 = (self.s**2)[:, None]  # s² per line, reused by every evaluation
        sn = self.s / (TWO_PI * float(np.mean(freqs_hz)))
        terms = np.stack([sn ** float(p) for p in RESIDUAL_POWERS], axis=1)
        self.rb = _stack(np.concatenate([terms, 1j * terms], axis=1))
        self.rb_pinv = _cho_solve(_gram_factor(self.rb), self.rb.T)
        self.y = self._perp_residual(_stack(h.T) * weights[None, :])
        self.weights = weights
        self.n_fixed = self.rb.shape[1]
        self.x: np.ndarray | None = None
        self.cost = math.inf
        self._normal: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # (x, JᵀJ, Jᵀr) last computed
        self._previous: dict | None = None

    def _perp_residual(self, v: np.ndarray) -> np.ndarray:
        return v - self.rb @ (self.rb_pinv @ v)

    def solve(self, x: np.ndarray) -> float:
        """Project out the linear constants at poles ``x``; return the cost (remembered for the last ``x``)."""
        if self.x is not None and np.array_equal(x, self.x):
            return self.cost
        state = self._state()
        if self._previous is not None and np.array_equal(x, self._previous["x"]):  # back from a rejected step
            self.__dict__.update(self._previous)
            self._previous = state
            return self.cost
        self._previous = state
        self.x = x.copy()
        omega = TWO_PI * x[0::2]
        zeta = np.exp(np.clip(x[1::2], LOG_ZETA_MIN, 0.0))
        s = self.s[:, None]
        d = self.s2 + (2.0 * zeta * omega) * s + omega**2
        self.q = self.s2 / d  # the mode columns s²/d before projection
        self.g = self._perp_residual(_stack(self.q))
        self.gram = _gram_inverse(self.g)
        self.coef = _apply_inverse(self.gram, self.g.T @ self.y)
        self.resid = self.y - self.g @ self.coef
        self.d, self.zeta, self.omega = d, zeta, omega
        flat = self.resid.ravel()
        self.cost = float(flat @ flat)
        return self.cost

    _FIELDS = ("x", "q", "g", "gram", "coef", "resid", "d", "zeta", "omega", "cost", "_normal")

    def _state(self) -> dict | None:
        """The evaluated point's arrays (kept for one more point: LM returns to it after a rejected step)."""
        return None if self.x is None else {k: getattr(self, k) for k in self._FIELDS}

    def project_out(self, v: np.ndarray) -> np.ndarray:
        """The part of ``v`` orthogonal to the residual terms and the mode columns."""
        vr = self._perp_residual(v)
        return vr - self.g @ _apply_inverse(self.gram, self.g.T @ vr)

    def inverse_gram_diagonal(self) -> np.ndarray:
        """Diagonal of the mode block of (BᵀB)⁻¹: how well each mode's constants are determined."""
        inv, scale = self.gram
        return np.diag(inv) * scale**2

    def projected_derivatives(self) -> np.ndarray:
        """∂(mode columns)/∂θ at the last solved point, projected off the residual terms and the mode columns."""
        s, qd = self.s[:, None], self.q / self.d  # s²/d²
        deriv = np.empty((2 * len(self.s), 2 * qd.shape[1]))
        deriv[:, 0::2] = _stack(qd * (-TWO_PI) * (2.0 * self.zeta * s + 2.0 * self.omega))
        deriv[:, 1::2] = _stack(qd * (-2.0 * self.omega * self.zeta) * s)
        return self.project_out(deriv)

    def normal_equations(self) -> tuple[np.ndarray, np.ndarray]:
        """JᵀJ and Jᵀr at the last solved point (remembered: the fit's covariance reuses the last step's)."""
        if self._normal is not None and self.x is not None and np.array_equal(self._normal[0], self.x):
            return self._normal[1], self._normal[2]
        pdb, c, jtj = self.jacobian()
        jtr = -np.sum((pdb.T @ self.resid) * c, axis=1)
        self._normal = (self.x.copy(), jtj, jtr)
        return jtj, jtr

    def jacobian(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The Kaufman Jacobian's pieces at the last solved point: projected derivatives, each parameter's mode
        constants (mode r's for both its parameters) and JᵀJ."""
        pdb = self.projected_derivatives()
        c = np.repeat(self.coef, 2, axis=0)
        return pdb, c, (pdb.T @ pdb) * (c @ c.T)


def _gram_factor(basis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cholesky factor of the column-scaled Gram matrix (small: one row and column per basis function)."""
    scale = 1.0 / np.sqrt(np.maximum(np.einsum("ij,ij->j", basis.conj(), basis).real, 1e-300))
    gram = (np.ascontiguousarray(basis.conj().T) @ basis) * np.outer(scale, scale)
    gram = gram + 1e-13 * np.eye(len(gram))
    return np.linalg.cholesky(gram), scale


def _gram_inverse(basis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of the column-scaled Gram matrix of a real basis with few columns (the mode columns: one
    evaluation's every solve reuses it) and the scale."""
    gram = basis.T @ basis
    scale = 1.0 / np.sqrt(np.maximum(gram.diagonal(), 1e-300))
    scaled = gram * scale[:, None] * scale[None, :]
    scaled.flat[:: len(scaled) + 1] += 1e-13
    if not math.isfinite(float(scaled.sum())):
        raise np.linalg.LinAlgError("mode columns are not finite")
    return np.linalg.inv(scaled), scale


def _apply_inverse(factor: tuple[np.ndarray, np.ndarray], rhs: np.ndarray) -> np.ndarray:
    """(BᵀB)⁻¹ rhs from :func:`_gram_inverse`."""
    inv, scale = factor
    return (inv @ (rhs * scale[:, None])) * scale[:, None]


def _cho_solve(factor: tuple[np.ndarray, np.ndarray], rhs: np.ndarray) -> np.ndarray:
    """(BᴴB)⁻¹ rhs from the scaled Cholesky factor."""
    low, scale = factor
    z = np.linalg.solve(low, rhs * scale[:, None])
    return np.linalg.solve(low.conj().T, z) * scale[:, None]


def _levenberg_marquardt(prob: _Problem, x0: np.ndarray, max_iter: int, dof: int) -> tuple[np.ndarray, bool]:
    """Minimise the projected cost over the poles; returns the solution and whether it converged.

    Converged when the undamped Gauss–Newton step promises less than ``GN_TOLERANCE`` of the noise variance
    (the poles then sit within a few hundredths of their σ of the minimum), or no step lowers the cost.
    """
    x, cost = x0.copy(), prob.solve(x0)
    lam = 1e-4
    for _ in range(max_iter):
        jtj, jtr = prob.normal_equations()
        scale = np.sqrt(np.maximum(np.diag(jtj), 1e-300))
        a = jtj / np.outer(scale, scale)
        b = jtr / scale
        try:
            gauss_newton = -float(b @ np.linalg.solve(a + 1e-12 * np.eye(len(x)), -b))
        except np.linalg.LinAlgError:
            gauss_newton = math.inf
        if 0.0 <= gauss_newton <= GN_TOLERANCE * cost / dof:
            return x, True
        while True:
            try:
                z = np.linalg.solve(a + lam * np.eye(len(x)), -b)
            except np.linalg.LinAlgError:
                return x, False
            predicted = -float(b @ z)  # first-order decrease the step promises
            if predicted <= 1e-12 * cost:
                prob.solve(x)
                return x, True
            step = z / scale
            new_cost = prob.solve(x + step)
            if new_cost < cost:
                break
            lam *= 10.0
            if lam > 1e8:
                prob.solve(x)
                return x, True
        x, cost = x + step, new_cost
        lam = max(lam / 10.0, 1e-9)
    return x, False


def fit_modes(
    freqs_hz: np.ndarray,
    h: np.ndarray,
    start: Sequence[tuple[float, float]],
    *,
    decay_rate_per_s: float = 0.0,
    channel_weights: np.ndarray | None = None,
    noise_inflation: float = 1.0,
    max_iter: int = 30,
) -> ModalFit:
    """Refine M modes (start: (frequency Hz, damping ratio) each) on the band ``freqs_hz`` of ``h`` (n_ch, n_f)."""
    weights = np.ones(h.shape[0]) if channel_weights is None else np.asarray(channel_weights, float)
    prob = _Problem(np.asarray(freqs_hz), h, decay_rate_per_s, weights)
    x0 = np.array([v for f, z in start for v in (f, math.log(max(z, 1e-5)))])
    m = len(start)
    n_data = 2 * len(freqs_hz) * h.shape[0]
    dof = max(n_data - (m + prob.n_fixed) * h.shape[0] - len(x0), 1)
    x, converged = _levenberg_marquardt(prob, x0, max_iter, dof)
    cost = prob.solve(x)
    sigma2 = cost / dof
    jtj, _ = prob.normal_equations()
    try:
        std = np.sqrt(np.clip(np.diag(np.linalg.inv(jtj)), 0.0, None) * sigma2 * noise_inflation)
    except np.linalg.LinAlgError:
        std = np.full(len(x), np.inf)
    zeta = np.exp(np.clip(x[1::2], LOG_ZETA_MIN, 0.0))
    inv_diag = prob.inverse_gram_diagonal()
    significance = np.sum(prob.coef**2, axis=1) / inv_diag / max(sigma2, 1e-300)
    constants_std = np.sqrt(np.outer(inv_diag * sigma2 * noise_inflation, 1.0 / weights**2))
    return ModalFit(
        frequencies_hz=x[0::2].copy(),
        damping_ratios=zeta,
        frequency_std_hz=std[0::2],
        damping_std=zeta * std[1::2],
        constants=prob.coef / weights[None, :],
        cost=cost,
        sigma2=sigma2,
        n_data=n_data,
        band_hz=(float(freqs_hz[0]), float(freqs_hz[-1])),
        converged=converged,
        channel_rms=np.sqrt(2.0 * np.mean(prob.resid**2, axis=0)) / weights,
        significance=significance,
        constants_std=constants_std,
    )


@dataclass(frozen=True)
class ForceNoise:
    """What the force channel's noise does to the FRF: per used impact, its force spectrum on the band lines,
    the force window's samples (index, value incl. the exponential window) and the noise σ (N)."""

    spectra: np.ndarray  # (n_imp, n_lines) complex force spectra F_i on the band
    line_index: np.ndarray  # (n_lines,) the band's FFT line numbers k
    n_fft: int
    windows: tuple[tuple[np.ndarray, np.ndarray], ...]  # per impact: (sample indices, window values)
    sigma_n: np.ndarray  # (n_imp,)
    _phases: dict = field(default_factory=dict, repr=False, compare=False)

    def phase(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Real and imaginary parts of exp(-2πi k t / N) for impact i's window samples t and the band's lines k
        (kept: reused by every fit; two real arrays because complex matrix products of this shape take a slow
        path)."""
        out = self._phases.get(i)
        if out is None:
            idx = self.windows[i][0]
            angle = (2.0 * math.pi / self.n_fft) * np.outer(idx, self.line_index)
            out = self._phases[i] = (np.cos(angle), -np.sin(angle))
        return out


class Linearised:
    """The fitted step's variable-projection problem frozen at its solution: maps data perturbations to poles."""

    def __init__(self, fit: ModalFit, freqs_hz: np.ndarray, h: np.ndarray, decay_rate_per_s: float,
                 channel_weights: np.ndarray | None) -> None:
        self.weights = np.ones(h.shape[0]) if channel_weights is None else np.asarray(channel_weights, float)
        self.prob = _Problem(np.asarray(freqs_hz), h, decay_rate_per_s, self.weights)
        x = np.array([v for f, z in zip(fit.frequencies_hz, fit.damping_ratios, strict=True)
                      for v in (f, math.log(max(z, 1e-12)))])
        self.prob.solve(x)
        self.pdb, self.c2, jtj = self.prob.jacobian()
        n = len(freqs_hz)
        self.p_c = self.pdb[:n] + 1j * self.pdb[n:]  # (n_lines, 2M)
        self.inv = np.linalg.inv(jtj)
        self.h = h

    def shift(self, h_other: np.ndarray) -> np.ndarray:
        """First-order change of the poles if the data were ``h_other`` (n_ch, n_lines) instead."""
        dy = _stack(((h_other - self.h) * self.weights[:, None]).T)
        jtr = -np.sum((self.pdb.T @ dy) * self.c2, axis=1)
        return -self.inv @ jtr

    def force_outer(self, noise: ForceNoise, impacts: Sequence[int], per_impact: bool) -> np.ndarray:
        """Σ σ² g gᵀ over the noise samples of the force windows of ``impacts``: for the average over all
        of them (H1 of the step), or for one impact's own FRF (``per_impact``)."""
        total_ff = np.sum(np.abs(noise.spectra) ** 2, axis=0)
        mix = np.repeat(self.prob.coef @ (self.h * self.weights[:, None]), 2, axis=0).T  # (n_lines, 2M)
        m2 = mix.shape[1]
        outer = np.zeros((m2, m2))
        for i in impacts:
            idx, vals = noise.windows[i]
            ff = np.abs(noise.spectra[i]) ** 2 if per_impact else total_ff
            a = -noise.spectra[i].conj() / np.where(ff > 0, ff, np.inf)
            q = np.conj(self.p_c) * mix * a[:, None]
            re, im = noise.phase(i)
            g = vals[:, None] * (re @ np.ascontiguousarray(q.real) - im @ np.ascontiguousarray(q.imag))
            outer += noise.sigma_n[i] ** 2 * (g.T @ g)
        return outer

    def force_covariance(self, noise: ForceNoise, impacts: Sequence[int], per_impact: bool = False) -> np.ndarray:
        """Covariance (2M × 2M, over (f_r, ln ζ_r) pairs) of the poles caused by the force channel's noise.

        H1 = Σ X F*/Σ|F|² with F_i = F_i° + δF_i gives δH = -H·Σ F_i* δF_i / Σ|F_i|² (first order): the same
        smooth relative error on every channel, correlated over many lines, which the residuals cannot reveal.
        Each noise sample in a force window perturbs the data by a known vector; the linearised estimate maps
        it to the poles: cov = (JᵀJ)⁻¹ (Σ σ² g gᵀ) (JᵀJ)⁻¹ with g = Jᵀ δy.
        """
        return self.inv @ self.force_outer(noise, impacts, per_impact) @ self.inv


def impact_shifts(fit: ModalFit, freqs_hz: np.ndarray, h: np.ndarray, h_each: np.ndarray, noise: ForceNoise, *,
                  decay_rate_per_s: float = 0.0, channel_weights: np.ndarray | None = None,
                  noise_inflation: float = 1.0, linearised: Linearised | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Each impact's own poles, to first order from the step's fit: (n_imp, 2M) shifts from the step's
    poles and their 1-σ (response noise scaled by the impact's share of the force energy, plus its own
    force noise). ``h_each``: (n_imp, n_ch, n_lines) single-impact FRFs X_i/F_i on the band."""
    lin = linearised or Linearised(fit, freqs_hz, h, decay_rate_per_s, channel_weights)
    response = np.clip(np.diag(lin.inv), 0.0, None) * fit.sigma2 * noise_inflation
    energy = np.sum(np.abs(noise.spectra) ** 2, axis=1)
    shifts, stds = [], []
    for i in range(h_each.shape[0]):
        shifts.append(lin.shift(h_each[i]))
        force = np.diag(lin.force_covariance(noise, [i], per_impact=True))
        stds.append(np.sqrt(response * float(energy.sum() / max(energy[i], 1e-300)) + np.clip(force, 0.0, None)))
    return np.array(shifts), np.array(stds)


def lscf_poles(freqs_hz: np.ndarray, h: np.ndarray, n_modes: int, *, decay_rate_per_s: float = 0.0,
               extra_numerator: int = 2, iterations: int = 3) -> np.ndarray:
    """Poles λ (s-plane, upper half) of a common-denominator fit on the band: linear least squares in a
    normalised local variable, reweighted by the previous denominator (Sanathanan–Koerner)."""
    s = TWO_PI * 1j * np.asarray(freqs_hz) + decay_rate_per_s
    centre = TWO_PI * 1j * 0.5 * (freqs_hz[0] + freqs_hz[-1])
    half = TWO_PI * 0.5 * (freqs_hz[-1] - freqs_hz[0])
    u = (s - centre) / half
    vn = u[:, None] ** np.arange(n_modes + extra_numerator + 1)[None, :]
    vd = u[:, None] ** np.arange(n_modes + 1)[None, :]
    weight = np.ones(len(u))
    roots = np.array([], dtype=complex)
    for _ in range(iterations):
        vw = vn / weight[:, None]
        factor = _gram_factor(vw)
        hv = (h / weight[None, :])[:, :, None] * vd[None, :, :]  # (n_ch, n_f, M + 1)
        hv = hv - vw @ _cho_solve(factor, np.ascontiguousarray(vw.conj().T) @ hv)
        a = hv[..., :n_modes].reshape(-1, n_modes)
        ah = np.ascontiguousarray(a.conj().T)  # a transposed complex view takes numpy's slow matmul path
        d = np.linalg.solve(ah @ a, -(ah @ hv[..., n_modes].ravel()))
        coeffs = np.concatenate([d, [1.0]])[::-1]
        roots = np.roots(coeffs)
        weight = np.maximum(np.abs(np.polyval(coeffs, u)), 1e-12)
        weight /= np.median(weight)
    return centre + half * roots


def pole_to_mode(pole: complex) -> tuple[float, float]:
    """(natural frequency Hz, damping ratio) of an s-plane pole."""
    omega = abs(pole)
    return omega / TWO_PI, -pole.real / omega if omega > 0 else 0.0
