"""An oracle ceiling for the blind hidden-effect worlds: how often could any method name the truth first?

It knows the blind generator (``bench/blind/discrepancy_worlds.py``) but not a world's truth: the 16 scenarios
(uniform prior), families (uniform) and their ``draw``, the size draw, calibration ranges, fault model and
``truth["noise"]``. It approximates ln p(rows | scenario) and ranks the truth classes by posterior, labelled as
``truth_name`` in ``bench/discrepancy_blind.py`` labels them (the four outside effects are one class, "unlisted").

Likelihood (the generator's): ln k = ln k_clean(θ) + s_rep + ε, ε ~ N(0, σ_pt(F_true)²), the seating s_rep ~
N(0, τ²) per type and repetition integrated analytically, the outlier fault (30 %: factors 1 ± U(0.08, 0.15) at
one step of one type in two repetitions) summed over its 231 places with the factors integrated (uniform in ln f);
a row identical to the one before it (the duplicate fault) is dropped. Per sub-hypothesis (scenario, families,
calibration sign): shape parameters are unit coordinates u fed to the family's own ``draw`` (prior uniform in u),
amplitudes ℓ = ln amp carry the generator's prior (ln z = ln(max |ln k/k_tripp| / σ_med1) 25 % log-uniform on
[0.5, 3], 75 % on [3, 15], times dln z/dℓ; half log-uniform in ``natural_range`` for misalignment), calibrations a
sign (½ each) and a uniform coordinate. Mode: Halton screen of u, amplitudes profiled, warm starts from the
single-family modes, L-BFGS-B from the best two. There ln L is taken quadratic (central differences, gradient kept
for modes on a bound, Hessian eigenvalues floored at 1) and integrated over the exact prior by sampling, ln z
linearised. ``--validate K`` redoes K worlds with a 3x screen, 4 starts and 300-draw importance sampling.
``--free-depth``: Tripp's depth (the generator's 3 mm) unknown, flat in ln t over 0.7–10 mm, integrated by Laplace
at its mode (Gauss-Newton on the seating Gaussian; the effects keep their 3 mm Tripp, times its depth change). Cannot:
integrate more than the best mode; treat the generator's clipping of an amplitude to its range (~2 % of effects)
other than as density; be exact where the posterior is far from Gaussian.

    python bench/oracle_ceiling.py --seeds 3 --noise 0.5,1,2 --workers 2 [--validate 6] [--free-depth] [--out F]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time
from collections import namedtuple
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from types import SimpleNamespace
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # one core per worker: tiny matrices, no BLAS threads
import numpy as np  # noqa: E402
from scipy.optimize import minimize, minimize_scalar  # noqa: E402
from scipy.special import expit, log_ndtr, ndtr  # noqa: E402
from scipy.stats import multivariate_t, qmc  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from oracle_report import label, report, truth_classes, validate  # noqa: E402

BLIND = Path(__file__).resolve().parent / "blind"
sys.path.insert(0, str(BLIND))
from blind_contact import RollerSpec, load_materials, load_rollers  # noqa: E402
from blind_families import OUTSIDE, PHYSICAL, Family, RollerLoads  # noqa: E402

if "blind_discrepancy_worlds" not in sys.modules:  # bench/ holds another discrepancy_worlds.py: a unique name
    _spec = importlib.util.spec_from_file_location("blind_discrepancy_worlds", BLIND / "discrepancy_worlds.py")
    sys.modules["blind_discrepancy_worlds"] = importlib.util.module_from_spec(_spec)
    _spec.loader.exec_module(sys.modules["blind_discrepancy_worlds"])
W = sys.modules["blind_discrepancy_worlds"]

LN_Z = (np.log(0.5), np.log(3.0), np.log(15.0))
LN_DENS = (np.log(W.SMALL_SHARE / np.log(6.0)), np.log((1 - W.SMALL_SHARE) / np.log(5.0)))
BAND_LO, BAND_HI = np.log([1.08, 0.85]), np.log([1.15, 0.92])  # ln f of the outlier fault's two bands
BAND_MID, BAND_HALF, BAND_NORM = (BAND_LO + BAND_HI) / 2, (BAND_HI - BAND_LO) / 2, np.log(0.5 / (BAND_HI - BAND_LO))
P_OUTLIERS, BAD = 0.3, -1e12
CAL = {"load_gain": lambda u, s: (1.02 + 0.08 * u if s > 0 else 0.92 + 0.06 * u, 0.0, 1.0),  # (gain, offset, k)
       "load_offset": lambda u, s: (1.0, s * (5.0 + 20.0 * u), 1.0),
       "modulus_scale": lambda u, s: (1.0, 0.0, 1.0 + s * (0.05 + 0.10 * u))}
Part = namedtuple("Part", "fam cal sign n_u", defaults=("", 1.0, 0))
"""One component of a hypothesis: an effect family (n_u shape coordinates, then ln amp) or a calibration."""
Hyp = namedtuple("Hyp", "scenario label log_prior parts layout")
"""A sub-hypothesis: a scenario with its families (and calibration sign) fixed, its ln prior weight, its layout."""
State = namedtuple("State", "rollers stack ln_tripp var norm point_norm smed beta")
"""What the true loads fix: rollers (per type, stacked), ln k_tripp, point variances, their norms, σ_med1, and β:
Tripp's compliance at depth t·e^δ is c·(1 + β·δ) (only the rail's ln(2t/a) term holds t)."""
DEPTH_SPAN = (np.log(0.7 / 3.0), np.log(10.0 / 3.0))
"""``--free-depth``: ln(t / 3 mm), flat over 0.7–10 mm, what a method must assume without the generator's depth."""


def logsumexp(v: np.ndarray | list[float]) -> float:
    """ln Σ exp(v), stable (scipy's is slow on small arrays)."""
    m = float(np.max(v := np.asarray(v, float)))
    return m if not np.isfinite(m) else m + float(np.log(np.sum(np.exp(v - m))))


def _ln_outlier(x: np.ndarray, s: np.ndarray) -> np.ndarray:
    """ln density of ln f + N(0, s²) at x, ln f uniform on either band with probability ½ (tails kept)."""
    a, s = np.abs(x[..., None] - BAND_MID), s[..., None]
    t1 = (BAND_HALF - a) / s
    p = ndtr(t1) - ndtr((-BAND_HALF - a) / s)
    lp = np.log(np.maximum(p, 1e-300))
    if (far := p < 1e-280).any():  # deep in the tail: the nearer edge alone
        lp[far] = log_ndtr(t1[far])
    return np.logaddexp(lp[..., 0] + BAND_NORM[0], lp[..., 1] + BAND_NORM[1])


def _draw(fam: Family, u: np.ndarray | list[float], rollers: list[RollerLoads]) -> tuple[dict[str, float], int]:
    """The family's own draw with its i-th uniform(lo, hi) read as lo + u_i (hi - lo); and how many it read."""
    it, used = iter([*u, *[0.5] * 8]), []
    rng = SimpleNamespace(uniform=lambda lo, hi: used.append(1) or lo + float(next(it)) * (hi - lo))
    return fam.draw(rng, rollers), len(used)


def _hyp(scenario: str, name: str, log_prior: float, parts: tuple[Part, ...]) -> Hyp:
    """A sub-hypothesis; layout: effect parts, parameter box (unit coordinates, ln amps), indices of each kind."""
    bounds = [b for p in parts for b in ([(0.0, 1.0)] * p.n_u + [tuple(np.log(p.fam.amp_range))]
                                         if p.fam is not None else [(0.0, 1.0)])]
    amp = [i for i, b in enumerate(bounds) if b != (0.0, 1.0)]
    layout = ([p for p in parts if p.fam], bounds, [i for i in range(len(bounds)) if i not in amp], amp)
    return Hyp(scenario, name, log_prior, parts, layout)


def hypotheses() -> list[Hyp]:
    """Every sub-hypothesis of the generator's scenarios with its prior (scenario, families, calibration, sign)."""
    specs, rail = load_rollers(), load_materials()[W.RAIL_MATERIAL]
    dummy = [RollerLoads(specs[t], rail, 0.2, np.linspace(38.0, 400.0, 11)) for t in W.ROLLER_TYPES]
    base, eff = -np.log(len(W.SCENARIOS)), {f.name: Part(f, n_u=_draw(f, [], dummy)[1])
                                              for fs in [*PHYSICAL.values(), OUTSIDE.values()] for f in fs}
    cals = [(c, Part(None, c, s)) for c in W.CALIBRATION for s in (1.0, -1.0)]
    out = [_hyp("none", "none", base, ())]
    for name, fams in PHYSICAL.items():
        out += [_hyp(name, label([name], []), base - np.log(len(fams)), (eff[f.name],)) for f in fams]
    out += [_hyp(f"outside_{n}", "unlisted", base, (eff[f.name],)) for n, f in OUTSIDE.items()]
    out += [_hyp(c, c, base - np.log(2), (p,)) for c, p in cals]
    for pair, (e1, e2) in W.PAIRS.items():
        out += [_hyp(pair, label([e1, e2], []), base - np.log(len(PHYSICAL[e1]) * len(PHYSICAL[e2])),
                    (eff[f1.name], eff[f2.name])) for f1 in PHYSICAL[e1] for f2 in PHYSICAL[e2]]
    for name, fams in PHYSICAL.items():
        w = base - np.log(len(PHYSICAL) * len(fams) * len(W.CALIBRATION) * 2)
        out += [_hyp("physical+calibration", label([name], [c]), w, (eff[f.name], p)) for f in fams for c, p in cals]
    return out


class World:
    """A world's rows (type x repetition x step, duplicate row dropped), the noise model and its likelihood."""

    def __init__(self, rows: list[dict[str, Any]], noise: dict[str, float], free_depth: bool = False) -> None:
        rows = sorted((r for i, r in enumerate(rows) if i == 0 or r != rows[i - 1]),
                      key=lambda r: (int(r["roller_type"]), int(r["repetition"]), float(r["load_n"])))
        self.shape = (len(W.ROLLER_TYPES), W.REPETITIONS, W.LOAD_STEPS)
        if len(rows) != int(np.prod(self.shape)):
            raise ValueError(f"expected {np.prod(self.shape)} rows (types x repetitions x steps), got {len(rows)}")
        self.noise, self.tau2 = noise, (noise["seat_sigma"] * noise["scale"]) ** 2
        self.f_rep, self.ra = (np.array([float(r[k]) for r in rows]) for k in ("load_n", "rail_ra_um"))
        self.y = np.log([float(r["stiffness_n_per_m"]) for r in rows]).reshape(self.shape)
        self.specs, self.rail = load_rollers(), load_materials()[W.RAIL_MATERIAL]
        sp = [self.specs[int(r["roller_type"])] for r in rows]
        self.stack_spec = RollerSpec(0, *(np.array([getattr(s, k) for s in sp]) for k in
                                          ("diameter_m", "contact_length_m", "total_length_m")), sp[0].material)
        self.ones, self.modes, self.base, self.free_depth = np.ones(W.LOAD_STEPS), {}, None, free_depth
        self.base = self.state(1.0, 0.0)

    def state(self, gain: float, offset: float) -> State:
        """The true loads F = (F_reported - offset)/gain and what they fix (cached without calibration)."""
        if gain == 1.0 and offset == 0.0 and self.base is not None:
            return self.base
        f = (self.f_rep - offset) / gain
        by_type = zip(W.ROLLER_TYPES, f.reshape(len(W.ROLLER_TYPES), -1), self.ra[::self.y[0].size], strict=True)
        stack, rel = RollerLoads(self.stack_spec, self.rail, self.ra, f), W._sigma_rel(f, self.noise)
        var = ((rel * self.noise["scale"]) ** 2).reshape(self.shape)
        point_norm = -0.5 * np.log(2 * np.pi * var)
        beta = (4.0 * self.rail.compliance / np.pi / stack.compliance(stack.line_load)).reshape(self.shape)
        return State([RollerLoads(self.specs[t], self.rail, float(ra), ft) for t, ft, ra in by_type], stack,
                     np.log(stack.tripp()), var, np.sum(point_norm, axis=2, keepdims=True), point_norm,
                     float(np.median(rel)), beta)

    def lnlike(self, lnk: np.ndarray, st: State) -> float:
        """ln p(rows | ln k_clean): Gaussian points, seating integrated per repetition, outlier fault summed; with
        ``free_depth`` Tripp's depth integrated over ``DEPTH_SPAN`` too (Laplace at its mode)."""
        if not self.free_depth:
            return self._lnlike(self.y - lnk.reshape(self.shape), st)
        r0, w, delta = self.y - lnk.reshape(self.shape), 1.0 / st.var, 0.0
        c = w @ self.ones + 1.0 / self.tau2  # per repetition: its points' weight plus the seating's
        for _ in range(4):  # Gauss-Newton on the seating Gaussian: k_tripp scales by 1/(1 + β·δ)
            r, ds = r0 + np.log1p(st.beta * delta), st.beta / (1.0 + st.beta * delta)
            grad = np.sum(w * r * ds) - np.sum((w * r) @ self.ones * ((w * ds) @ self.ones) / c)
            curv = np.sum(w * ds * ds) - np.sum(((w * ds) @ self.ones) ** 2 / c)
            delta = float(np.clip(delta - grad / curv, *DEPTH_SPAN))
        return (self._lnlike(r0 + np.log1p(st.beta * delta), st) + 0.5 * np.log(2 * np.pi / curv)
                - np.log(DEPTH_SPAN[1] - DEPTH_SPAN[0]))

    def _lnlike(self, r: np.ndarray, st: State) -> float:
        """ln p(rows | residuals r = ln k_obs − ln k_clean), the depth given."""
        w, it2 = 1.0 / st.var, 1.0 / self.tau2
        wr = w * r
        a, b, c = ((v @ self.ones)[..., None] for v in (wr * r, wr, w))
        lg = -0.5 * (a - b * b / (it2 + c)) - 0.5 * np.log1p(self.tau2 * c) + st.norm
        bj, cj = b - wr, c - w  # each point left out of its repetition
        d = -0.5 * (a - wr * r - bj * bj / (it2 + cj)) - 0.5 * np.log1p(self.tau2 * cj) - lg + st.norm - st.point_norm
        d = d + _ln_outlier(r - bj / (it2 + cj), np.sqrt(st.var + 1.0 / (it2 + cj)))
        pairs = np.concatenate([d[:, 0] + d[:, 1], d[:, 0] + d[:, 2], d[:, 1] + d[:, 2]]).ravel()
        mix = np.logaddexp(np.log(1 - P_OUTLIERS), np.log(P_OUTLIERS / pairs.size) + logsumexp(pairs))
        return float(lg.sum() + mix)


def evaluate(world: World, hyp: Hyp, x: np.ndarray) -> tuple[float, list[float]]:
    """(ln L, ln z of each effect) at parameters x."""
    gain, offset, kscale, i, effects = 1.0, 0.0, 1.0, 0, []
    for p in hyp.parts:
        if p.fam is None:
            (gain, offset, kscale), i = CAL[p.cal](float(x[i]), p.sign), i + 1
        else:
            effects.append((p.fam, x[i:i + p.n_u], float(x[i + p.n_u])))
            i += p.n_u + 1
    if np.min(world.f_rep) <= offset:  # a true load ≤ 0: impossible
        return BAD, [0.0] * len(effects)
    st = world.state(gain, offset)
    lnk, sizes = st.ln_tripp + np.log(kscale), []
    with np.errstate(all="ignore"):
        for fam, u, ell in effects:
            lr = np.log(fam.apply(st.stack, _draw(fam, u, st.rollers)[0], float(np.exp(ell)))) - st.ln_tripp
            if not np.all(np.isfinite(lr)):
                return BAD, [0.0] * len(effects)
            sizes.append(float(np.log(max(np.max(np.abs(lr)), 1e-300) / st.smed)))
            lnk = lnk + lr
    return world.lnlike(lnk, st), sizes


def ln_amp_prior(fam: Family, ell: np.ndarray, lz: np.ndarray, jac: np.ndarray, soft: bool) -> np.ndarray:
    """The generator's prior density of ln amp: the size (ln z) part, mixed with ``natural_range`` if any."""
    if soft:  # the jump at z = 3 and the edges smoothed, to search
        dens = np.log(np.exp(LN_DENS[0]) + (np.exp(LN_DENS[1]) - np.exp(LN_DENS[0])) * expit((lz - LN_Z[1]) / 0.02))
        size = dens - 0.5 * ((lz - np.clip(lz, LN_Z[0], LN_Z[2])) / 0.05) ** 2
    else:
        size = np.where((lz >= LN_Z[0]) & (lz <= LN_Z[2]), np.where(lz < LN_Z[1], *LN_DENS), -np.inf)
    size = size + np.log(np.abs(jac) + 1e-12)
    if fam.natural_range is None:
        return size
    lo, hi = np.log(fam.natural_range)
    nat = -np.log(hi - lo) - (0.5 * ((ell - np.clip(ell, lo, hi)) / 0.05) ** 2 if soft
                              else np.where((ell >= lo) & (ell <= hi), 0.0, np.inf))
    return np.logaddexp(size, nat) + np.log(0.5)


def ln_prior_at(hyp: Hyp, xs: np.ndarray, lz: np.ndarray, jac: np.ndarray, soft: bool = False) -> np.ndarray:
    """ln prior density at points xs (rows) given each effect's ln z and dln z/dℓ there (soft: smoothed in ln z)."""
    effects, bnd, _, l_idx = hyp.layout
    lo, hi = np.array(bnd).T
    out = np.where(np.all((xs >= lo) & (xs <= hi), axis=1), 0.0, -np.inf)
    for e, (p, j) in enumerate(zip(effects, l_idx, strict=True)):
        out = out + ln_amp_prior(p.fam, xs[:, j], lz[:, e], jac[:, e], soft)
    return out


def phi(world: World, hyp: Hyp, x: np.ndarray) -> tuple[float, list[float]]:
    """(ln L + ln prior with soft edges and dln z/dℓ taken as 1, ln z of each effect): the search objective."""
    lnl, sizes = evaluate(world, hyp, x)
    v = lnl + sum(float(ln_amp_prior(p.fam, x[j], z, 1.0, True))
                  for p, j, z in zip(hyp.layout[0], hyp.layout[3], sizes, strict=True))
    return (v if np.isfinite(v) else BAD), sizes


def _profile(world: World, hyp: Hyp, x: np.ndarray, slot: int) -> np.ndarray:
    """The best ln amp of one effect, the rest held: secant in ln z to a few sizes, then Brent."""
    j = hyp.layout[3][slot]
    (lo, hi), x = hyp.layout[1][j], x.copy()

    def at(ell: float) -> tuple[float, float]:
        x[j] = np.clip(ell, lo, hi)
        v, sizes = phi(world, hyp, x)
        return v, sizes[slot]

    l1 = float(np.clip(0.5 * (lo + hi) + np.log(5.0) - (z0 := at(0.5 * (lo + hi))[1]), lo, hi))
    z1 = at(l1)[1]
    slope = float(np.clip((z1 - z0) / (l1 - 0.5 * (lo + hi)), 0.2, 5.0)) if abs(l1 - 0.5 * (lo + hi)) > 1e-6 else 1.0
    best = max((float(np.clip(l1 + (np.log(z) - z1) / slope, lo, hi)) for z in (0.8, 2.0, 5.0, 12.0)),
               key=lambda ell: at(ell)[0])
    res = minimize_scalar(lambda ell: -at(ell)[0], bounds=(max(lo, best - 0.7 / slope), min(hi, best + 0.7 / slope)),
                          method="bounded", options={"xatol": 0.02, "maxiter": 10})
    x[j] = float(np.clip(res.x, lo, hi))
    return x


def _search(world: World, hyp: Hyp, n_screen: int, n_starts: int) -> np.ndarray:
    """The mode: Halton screen and single-family warm starts (amplitudes profiled), L-BFGS-B from the best."""
    effects, bounds, u_idx, l_idx = hyp.layout
    lo, starts, i = np.array([b[0] for b in bounds], float), [], 0
    for u in qmc.Halton(len(u_idx), seed=7).random(n_screen) if u_idx and n_screen else [np.zeros(len(u_idx))]:
        starts.append(lo.copy())
        starts[-1][u_idx] = u
    for p in hyp.parts:
        for c in ((0.25, 0.75) if len(effects) == 1 else (0.5,)) if p.fam and len(hyp.parts) > 1 else ():
            if p.fam.name in world.modes:
                starts.append(lo.copy())
                starts[-1][u_idx], starts[-1][i:i + p.n_u + 1] = c, world.modes[p.fam.name]
        i += p.n_u + 1
    screened = []
    for x in starts:
        for slot, j in enumerate(l_idx):
            x = _profile(world, hyp, x, slot) if x[j] == lo[j] else x
        screened.append((phi(world, hyp, x)[0], x))
    best = max(screened, key=lambda t: t[0])
    for _, x0 in sorted(screened, key=lambda t: -t[0])[:n_starts]:
        res = minimize(lambda x: -phi(world, hyp, x)[0], x0, method="L-BFGS-B", bounds=bounds, options={"maxiter": 60})
        best = (-res.fun, res.x) if -res.fun > best[0] else best
    if len(hyp.parts) == 1 and effects:
        world.modes[effects[0].fam.name] = np.asarray(best[1], float)
    return np.asarray(best[1], float)


def _curvature(world: World, hyp: Hyp, x: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """ln L, its gradient and -Hessian, each ln z and its gradient at x by central differences (steps adapted)."""
    (k, eye), (f0, z0), h = (len(x), np.eye(len(x))), evaluate(world, hyp, x), np.full(len(x), 2e-3)
    for _ in range(2):  # the steps then adapted to the curvature (about 0.3 σ)
        fz = [[evaluate(world, hyp, x + s * h[i] * eye[i]) for s in (1, -1)] for i in range(k)]
        diag = np.array([(fz[i][0][0] + fz[i][1][0] - 2 * f0) / h[i] ** 2 for i in range(k)])
        h, used = np.minimum(2e-3, 0.3 / np.sqrt(np.maximum(-diag, 1e-12))), h
    h, hess = used, np.diag(diag)
    for i in range(k):
        for j in range(i + 1, k):
            v = [evaluate(world, hyp, x + a * h[i] * eye[i] + b * h[j] * eye[j])[0]
                 for a, b in ((1, 1), (1, -1), (-1, 1), (-1, -1))]
            hess[i, j] = hess[j, i] = (v[0] - v[1] - v[2] + v[3]) / (4 * h[i] * h[j])
    grad_z = np.array([[(fz[i][0][1][e] - fz[i][1][1][e]) / (2 * h[i]) for i in range(k)] for e in range(len(z0))])
    grad = np.array([(fz[i][0][0] - fz[i][1][0]) / (2 * h[i]) for i in range(k)])
    return f0, grad, -hess, np.array(z0), grad_z.reshape(len(z0), k)


def evidence(world: World, hyp: Hyp, fine: bool = False) -> float:
    """ln p(rows | sub-hypothesis): Laplace at the mode (fine: a wider search and importance sampling)."""
    if not hyp.parts:
        return evaluate(world, hyp, np.zeros(0))[0]
    n_u, l_idx = len(hyp.layout[2]), hyp.layout[3]
    n_screen = min(16, 3 + 4 * n_u) if len(hyp.parts) == 1 else min(6, 1 + 2 * n_u)
    x = _search(world, hyp, (3 if fine else 1) * n_screen if n_u else 0, 4 if fine else 2)
    x = np.clip(x, *(np.array(hyp.layout[1]).T + [[2e-3], [-2e-3]]))  # a mode on a bound: differences inside
    f0, grad, hess, z0, gz = _curvature(world, hyp, x)
    lam, vec = np.linalg.eigh(0.5 * (hess + hess.T))
    lam = np.maximum(lam, 1.0)
    cov, jac, rng, n = (vec / lam) @ vec.T, gz[:, l_idx].diagonal(), np.random.default_rng(11), 4000
    if not fine:  # ln L quadratic around x (with its gradient: modes on a bound) integrated over the prior
        xs = rng.multivariate_normal(x, cov, n, method="eigh")
        lz, tilt = z0 + (xs - x) @ gz.T, (xs - x) @ grad  # the soft edges only if no draw is inside the support
        mass = next((m for soft in (False, True) if np.isfinite(m := logsumexp(
            tilt + ln_prior_at(hyp, xs, lz, np.broadcast_to(jac, lz.shape), soft)))), -np.inf)
        return f0 + 0.5 * len(x) * np.log(2 * np.pi) - 0.5 * float(np.sum(np.log(lam))) + mass - np.log(n)
    n, prop = 300, multivariate_t(x, 1.5**2 * cov, df=4)
    xs = np.asarray(prop.rvs(n, random_state=rng), float).reshape(n, len(x))
    lnl, lz, jc = np.zeros(n), np.zeros((n, len(l_idx))), np.zeros((n, len(l_idx)))
    for m, xm in enumerate(xs):
        lnl[m], lz[m] = evaluate(world, hyp, xm)
        for e, j in enumerate(l_idx):
            jc[m, e] = (evaluate(world, hyp, xm + 1e-4 * np.eye(len(x))[j])[1][e] - lz[m, e]) / 1e-4
    return logsumexp(lnl + ln_prior_at(hyp, xs, lz, jc) - prop.logpdf(xs)) - np.log(n)


def classify(rows: list[dict[str, Any]], noise: dict[str, float], fine: bool = False, free_depth: bool = False
             ) -> dict[str, float]:
    """ln posterior (unnormalised) of every truth class, best first."""
    world, terms = World(rows, noise, free_depth), {}
    for hyp in hypotheses():
        terms.setdefault(hyp.label, []).append(hyp.log_prior + evidence(world, hyp, fine))
    return dict(sorted(((k, logsumexp(v)) for k, v in terms.items()), key=lambda kv: -kv[1]))


def run_world(task: tuple[str, int, float, bool, bool]) -> dict[str, Any]:
    """Generate one world and classify it (a worker's job)."""
    (scenario, seed, scale, fine, free_depth), t0 = task, time.perf_counter()
    ds = W.generate(scenario, seed, scale)
    post = classify(ds.rows, ds.truth["noise"], fine, free_depth)
    truth, seen = truth_classes(ds.truth)
    return {"scenario": scenario, "seed": seed, "scale": scale, "truth": truth, "top": next(iter(post)), "seen": seen,
            "size": float(ds.truth["size_sigma"]), "post": post, "seconds": time.perf_counter() - t0}


def main(argv: list[str] | None = None) -> int:
    """Run the oracle over the generator's scenarios x seeds x noise scales and print its accuracy."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3, help="evaluation seeds 0..N-1 per scenario")
    ap.add_argument("--noise", default="0.5,1,2", help="noise scales, comma-separated")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--validate", type=int, default=0, help="also redo K worlds (noise 1, seed 0) finely")
    ap.add_argument("--free-depth", action="store_true",
                    help="Tripp's depth unknown (flat in ln t over 0.7-10 mm), as it is to any method")
    ap.add_argument("--out", type=Path, help="also write every world's result (posterior included) as JSON")
    args = ap.parse_args(argv)
    t0, scales = time.perf_counter(), [float(v) for v in args.noise.split(",")]
    tasks = [(sc, s, x, False, args.free_depth) for x in scales for sc in W.SCENARIOS for s in range(args.seeds)]
    picks = W.SCENARIOS[::max(1, len(W.SCENARIOS) // max(args.validate, 1))][:args.validate]
    checks = [(sc, 0, 1.0, fine, args.free_depth) for fine in (False, True) for sc in picks]
    with ProcessPoolExecutor(args.workers) as pool:
        results = list(pool.map(run_world, tasks + checks, chunksize=1))
    report(results[:len(tasks)], scales if tasks else [], W.SCENARIOS, args.out)
    if checks:
        validate(results[len(tasks):len(tasks) + len(checks) // 2], results[len(tasks) + len(checks) // 2:])
    print(f"{len(tasks) + len(checks)} worlds on {args.workers} workers in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
