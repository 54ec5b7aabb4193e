"""Per-roller stiffness: the three contact modes and the rig model solved for the three roller stiffnesses.

The bounce frequency fixes (mostly) the rollers' mean stiffness, the tilt pair's split how unequal they
are; which roller differs is in the tilt modes' orientation — frequencies alone are the same for any
permutation of the rollers — so the inverse matches the rig model (``labctl.physics.rig_modes``, three
stiffnesses) to the bounce frequency, the tilt split *and* the angle of each tilt mode's shape inside the
model's tilt subspace over the live sensors. The tilt pair's mean frequency is not used: it depends on
the discs' inertia, which the rig file's uncertainties do not cover, and would pull the mean stiffness
away from the bounce (Eq. 4) on a rig whose inertia is off. Weighted least squares in ln k, from a few starts around the
circle of deviations the split allows; the covariance comes from the weighted Jacobian at the solution,
whose condition number is reported. An unresolved tilt pair cannot say which roller differs: the three
values are then the equal-roller solution, their spread bounded by the split the data could have hidden.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtri

from labctl.errors import ModelDomainError
from labctl.physics import RigConfig
from labctl.physics.rig import ContactModeModel, contact_modes_hz, point_displacement
from labctl.processing.cross_axis import cross_axis_variance
from labctl.processing.rig_memo import RigMemo
from labctl.processing.search import ContactModes
from labctl.processing.stiffness import Stiffness

DIFFER_LEVEL = 0.001  # two-sided level of the "this roller differs from the others" test
ANGLE_FALLBACK_RAD = 0.05
JOINT_DESCENTS = 3  # Gauss–Newton descents from the best starts of the joint (rollers and asymmetry) problem
JOINT_ITER = 12
POOR_FIT_COST = 36.0  # χ² of the joint fit's 6 whitened residuals beyond which the other descents are tried
# The "roller or rig asymmetry" warning: when discs asymmetric as the rig file allows (each component of the
# asymmetry normal with its σ) would give a split this large with probability below 0.05: |a| > σ·√(-2 ln 0.05)
ASYMMETRY_WARNING_LEVEL = 0.05
UNUSUAL_ASYMMETRY = math.sqrt(-2.0 * math.log(ASYMMETRY_WARNING_LEVEL))


@dataclass(frozen=True)
class RollerStiffnesses:
    """k per roller (rig-file order) with the modal part of their covariance, and what the data could tell."""

    values_n_per_m: tuple[float, float, float]
    covariance: np.ndarray  # (3, 3) N²/m²: modal fit, sensors' cross-axis coupling and the discs' inertia asymmetry
    # (the rig parameters common to all three are excluded)
    resolved: bool  # False: tilt pair unresolved, equal-roller values with the spread the data could hide
    condition: float | None  # of the weighted inverse (None when not solved)
    z: tuple[float, float, float]  # each roller's deviation from the mean over its uncertainty
    differing: tuple[int, ...]  # 0-based rollers whose deviation passes the test at DIFFER_LEVEL
    # z with the rig's inertia asymmetry taken as known to be zero: what the split alone would say
    z_symmetric: tuple[float, float, float] = (0.0, 0.0, 0.0)
    asymmetry_equivalent: float = 0.0  # the discs' inertia asymmetry (I1 - I2)/I that alone gives the split

    @property
    def std_n_per_m(self) -> tuple[float, float, float]:
        d = np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))
        return (float(d[0]), float(d[1]), float(d[2]))

    @property
    def mean_n_per_m(self) -> float:
        return float(np.mean(self.values_n_per_m))

    @property
    def mean_std_n_per_m(self) -> float:
        return float(math.sqrt(max(float(np.ones(3) @ self.covariance @ np.ones(3)), 0.0)) / 3.0)


def _build_sensor_map(rig: RigConfig, names: Sequence[str]) -> np.ndarray:
    eye = np.eye(6)
    by_channel: dict[str, np.ndarray] = {}
    for s in rig.sensors:
        cols = np.array([point_displacement(eye[j], s.disc, s.x_m, s.y_m, s.z_m, s.angle_rad) for j in range(6)]).T
        for ch, row in zip(s.channels, cols, strict=True):
            by_channel[ch] = row
    return np.array([by_channel[c] for c in names])


_sensor_map = RigMemo(_build_sensor_map)
"""(n_ch, 6) linear map from the rig's DOF vector to each channel's displacement (the rig model's own)."""


def _tilt_basis(model: ContactModeModel, sensors: np.ndarray, k: float) -> np.ndarray:
    """Orthonormal basis (n_live, 2) of the equal-roller model's tilt subspace over the live channels."""
    _, shapes = model(np.full(3, k))
    u, _, _ = np.linalg.svd(sensors @ shapes[:, 1:], full_matrices=False)
    return u[:, :2]


def _model(model: ContactModeModel, k: np.ndarray, sensors: np.ndarray, basis: np.ndarray,
           asymmetry: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """For n sets of stiffnesses (n, 3) (and inertia asymmetries (n, 2)): (bounce, tilt lo, tilt hi) Hz (n, 3)
    and the angles (n, 2) of the two tilt shapes over the live channels inside the equal-roller tilt subspace
    ``basis``."""
    freqs, shapes = model.many(k, asymmetry)
    p = np.einsum("ca,cj,njm->nam", basis, sensors, shapes[:, :, 1:])  # (n, 2 basis components, 2 tilt modes)
    return freqs, np.arctan2(p[:, 1], p[:, 0])


def _angle(basis: np.ndarray, v: np.ndarray) -> tuple[float, np.ndarray]:
    p = basis.T @ v
    return math.atan2(float(p[1]), float(p[0])), p


def _wrap(d: np.ndarray) -> np.ndarray:
    """Angle differences modulo π (a mode shape's sign is arbitrary), in (-π/2, π/2]."""
    return (d + 0.5 * math.pi) % math.pi - 0.5 * math.pi


def _split_per_deviation(rig: RigConfig, k: float) -> float:
    """d(tilt split)/dε for roller stiffnesses k·(1 + ε·(1, -½, -½)) at small ε (Hz per unit ε)."""
    eps = 1e-3
    _, lo, hi = contact_modes_hz(rig, k * (1.0 + eps * np.array([1.0, -0.5, -0.5])))
    return (hi - lo) / eps


def _split_per_asymmetry(rig: RigConfig, k: float) -> float:
    """d(tilt split)/d|asymmetry| for equal rollers k (Hz per unit (I1 - I2)/I)."""
    a = 1e-3
    f, _ = ContactModeModel.of(rig).many(np.full((1, 3), k), np.array([[a, 0.0]]))
    return float(f[0, 2] - f[0, 1]) / a


def _jacobian(residuals, u: np.ndarray, r0: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Forward differences, every parameter's step evaluated in one batch of ``residuals`` ((n, p) → (n, m))."""
    return ((residuals(u + h * np.eye(len(u))) - r0) / h).T


MAX_HALVINGS = 6  # a step that still raises the cost at 1/64 of its length ends the descent
STEP_TOLERANCE = 0.01  # converged when a full Gauss–Newton step moves every parameter by less than this share
# of its 1-σ: the solution then sits far closer to the minimum than its stated uncertainty can tell


def _gauss_newton(residuals, u0: np.ndarray, max_iter: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Minimise |residual(u)|² (a few parameters, whitened residuals, a good start; ``residuals`` maps a batch of
    parameter sets (n, p) to theirs (n, m)): Gauss–Newton steps, halved when they do not lower the cost;
    returns the solution and the Jacobian there (at the last step's start when that step was below
    ``STEP_TOLERANCE`` of the parameters' σ)."""

    def residual(v: np.ndarray) -> np.ndarray:
        return residuals(v[None, :])[0]

    u = u0.copy()
    r = residual(u)
    jac = _jacobian(residuals, u, r)
    for _ in range(max_iter):
        step = np.linalg.lstsq(jac, -r, rcond=None)[0]
        try:
            sigma = np.sqrt(np.clip(np.diag(np.linalg.inv(jac.T @ jac)), 0.0, None))
        except np.linalg.LinAlgError:
            sigma = np.zeros(len(u))
        cost = float(r @ r)
        for _ in range(MAX_HALVINGS):
            r_new = residual(u + step)
            if float(r_new @ r_new) <= cost:
                break
            step = 0.5 * step
        else:
            break
        u, r = u + step, r_new
        if np.all(np.abs(step) < STEP_TOLERANCE * sigma) or float(np.max(np.abs(step))) < 1e-7:
            break
        jac = _jacobian(residuals, u, r)
    return u, jac


def _differing(values: np.ndarray, cov: np.ndarray, model_rel: float) -> tuple[tuple[float, float, float],
                                                                             tuple[int, ...]]:
    a = np.eye(3) - 1.0 / 3.0
    cov_d = a @ (cov + np.diag((model_rel * values) ** 2)) @ a.T
    d = a @ values
    z = d / np.sqrt(np.maximum(np.diag(cov_d), 1e-300))
    limit = -ndtri(DIFFER_LEVEL / 2)
    return (float(z[0]), float(z[1]), float(z[2])), tuple(i for i in range(3) if abs(z[i]) > limit)


def equal_rollers(rig: RigConfig, k: float, k_std: float, split_std_hz: float) -> RollerStiffnesses:
    """Unresolved tilt pair: all three at the equal-roller value; each roller's 1-σ adds the deviation that
    a split of ``split_std_hz`` (one σ of a split the data could hide) would mean, and the one a 1-σ inertia
    asymmetry of the discs could cancel."""
    slope = abs(_split_per_deviation(rig, k))
    # a roller deviation and the discs' inertia asymmetry can cancel in the split: both bound what is hidden
    hidden = math.hypot(split_std_hz, rig.uncertainty.inertia_asymmetry_rel * abs(_split_per_asymmetry(rig, k)))
    dev = k * hidden / slope if slope > 0 and math.isfinite(hidden) else math.inf
    a = np.eye(3) - 1.0 / 3.0
    cov = np.full((3, 3), k_std**2) + dev**2 * a
    return RollerStiffnesses((k, k, k), cov, False, None, (0.0, 0.0, 0.0), ())


def solve_rollers(
    rig: RigConfig,
    names: Sequence[str],
    live: np.ndarray,
    freqs_hz: Sequence[float],
    freqs_std_hz: Sequence[float],
    tilt_constants: np.ndarray,
    tilt_constants_std: np.ndarray | None,
    k_equal: float,
    split_std_hz: float | None = None,
) -> RollerStiffnesses:
    """Three roller stiffnesses from (bounce, tilt lo, tilt hi) with 1-σ and the two tilt shapes (2, n_ch);
    ``split_std_hz``: the tilt split's 1-σ when known better than from the two stds (correlated errors)."""
    measured = np.asarray(freqs_hz, float)
    sig = np.maximum(np.asarray(freqs_std_hz, float), 1e-9 * measured)
    sig_split = math.hypot(sig[1], sig[2]) if split_std_hz is None else max(split_std_hz, 1e-9 * measured[1])
    model = ContactModeModel.of(rig)
    sensors = _sensor_map(rig, names)[live]
    basis = _tilt_basis(model, sensors, k_equal)
    cross = cross_axis_variance(rig, names, np.asarray(tilt_constants, float))
    meas_angles, sig_angles, projections = [], [], []
    for r in range(2):
        v = tilt_constants[r][live]
        ang, p = _angle(basis, v)
        norm_p = float(np.linalg.norm(p))
        std_ok = tilt_constants_std is not None and np.all(np.isfinite(tilt_constants_std[r][live]))
        if norm_p > 0 and (std_ok or np.any(cross[r][live] > 0)):
            perp = np.array([-p[1], p[0]]) / norm_p
            var_c = cross[r][live] + (tilt_constants_std[r][live] ** 2 if std_ok else 0.0)
            var = float(np.sum((basis @ perp) ** 2 * var_c))
            sig_angles.append(max(math.sqrt(var) / norm_p, 1e-6) if std_ok else max(math.sqrt(var) / norm_p,
                                                                                    ANGLE_FALLBACK_RAD))
        else:
            sig_angles.append(ANGLE_FALLBACK_RAD)
        meas_angles.append(ang)
        projections.append(norm_p)
    # Two modes much closer than their bandwidth: the data fix the sum of their modal constants and their
    # difference times the split, so an error in the split (relative σ_split/split) mixes the two shapes — each
    # shape turns by ½·(σ_split/split)·|other|/|own| inside the tilt subspace (their shapes near-orthogonal).
    split = measured[2] - measured[1]
    mixing = 0.5 * sig_split / max(abs(split), 1e-12)
    for r in range(2):
        other = projections[1 - r] / max(projections[r], 1e-300)
        sig_angles[r] = math.hypot(sig_angles[r], min(mixing * other, 0.5 * math.pi))
    sig_asym = rig.uncertainty.inertia_asymmetry_rel
    per_asymmetry = _split_per_asymmetry(rig, k_equal)

    def residuals(u: np.ndarray) -> np.ndarray:
        asym = u[:, 3:5] if u.shape[1] == 5 else None
        f, angles = _model(model, np.exp(u[:, :3]), sensors, basis, asym)
        cols = [(f[:, 0] - measured[0]) / sig[0], ((f[:, 2] - f[:, 1]) - (measured[2] - measured[1])) / sig_split,
                *(_wrap(angles - np.asarray(meas_angles)) / np.asarray(sig_angles)).T]
        if asym is not None:  # the rig file's prior on the asymmetry: what the data must overcome
            cols += [asym[:, 0] / sig_asym, asym[:, 1] / sig_asym]
        return np.column_stack(cols)

    eps0 = split / max(abs(_split_per_deviation(rig, k_equal)), 1e-300)
    theta = np.radians(np.arange(0.0, 360.0, 45.0))[:, None]
    starts = np.log(k_equal * np.clip(1.0 + eps0 * np.cos(theta - np.radians([0.0, 120.0, 240.0])), 0.2, 5.0))
    best = starts[int(np.argmin(np.sum(residuals(starts) ** 2, axis=1)))]
    u, jac = _gauss_newton(residuals, best)
    if sig_asym > 0:  # the asymmetry as two more parameters with the rig file's prior: k's covariance holds it
        u0 = np.concatenate([u, [0.0, 0.0]])

        def cost(t: tuple[np.ndarray, np.ndarray]) -> float:
            return float(np.sum(residuals(t[0][None])[0] ** 2))

        # Symmetric discs fit the data: the joint optimum lies a step or two away (the prior holds the asymmetry
        # near zero). Otherwise the data want an asymmetry: starts from the split by the asymmetry alone at any
        # orientation and halves of both, the three best refined, the lowest cost kept (the angles' residuals are
        # not convex far from the solution: rollers ±15 % on discs 5.5 % asymmetric stalled one descent at 600 σ).
        best_try = _gauss_newton(residuals, u0, max_iter=2)
        if cost(best_try) > POOR_FIT_COST:
            a0 = abs(split) / max(abs(per_asymmetry), 1e-300)
            circle = np.column_stack([np.cos(2 * theta[:, 0]), np.sin(2 * theta[:, 0])])
            log_eq = np.full((len(theta), 3), math.log(k_equal))
            joint = np.vstack([np.column_stack([log_eq, a0 * circle]),
                               np.column_stack([0.5 * (starts + log_eq), 0.5 * a0 * circle])])
            ranked = np.argsort(np.sum(residuals(joint) ** 2, axis=1))[:JOINT_DESCENTS]
            tries = [_gauss_newton(residuals, best_try[0], max_iter=JOINT_ITER),
                     *(_gauss_newton(residuals, joint[i], max_iter=JOINT_ITER) for i in ranked)]
            best_try = min(tries, key=cost)
        u, jac_all = best_try
        jac = jac_all[:-2, :3]  # symmetric discs: the data's rows, the rollers' columns
    else:
        jac_all = jac
    k = np.exp(u[:3])
    try:
        cov_u = np.linalg.inv(jac_all.T @ jac_all)[:3, :3]
        cov_sym = np.linalg.inv(jac.T @ jac)
        condition = float(np.linalg.cond(jac_all))
    except np.linalg.LinAlgError:
        cov_u, cov_sym, condition = np.full((3, 3), np.inf), np.full((3, 3), np.inf), math.inf
    kk = np.outer(k, k)
    cov = cov_u * kk
    z, differing = _differing(k, cov, rig.uncertainty.model_rel)
    z_sym, _ = _differing(k, cov_sym * kk, rig.uncertainty.model_rel)
    equivalent = abs(split) / max(abs(per_asymmetry), 1e-300)
    return RollerStiffnesses((float(k[0]), float(k[1]), float(k[2])), cov, True, condition, z, differing, z_sym,
                             equivalent)


# A per-roller solution is taken only when it is physically credible: rollers of one type differ by less than
# this ratio, and their mean stays this close to the bounce's equal-roller value (rollers at ±15 % move it ~2 %).
MAX_ROLLER_RATIO = 2.0
MAX_MEAN_SHIFT = 0.08


def per_roller(rig: RigConfig, names: tuple[str, ...], live: np.ndarray, modes: ContactModes, k_eq: Stiffness,
             warnings: list[str], blow_dependent: bool = False) -> RollerStiffnesses:
    """Per-roller stiffnesses from the three contact modes (equal-roller values when the pair is unresolved, or
    when the blows move the modes: they move the tilt pair by other amounts than the bounce), with a warning
    naming the rollers that differ beyond their uncertainty."""
    fit, cls = modes.fit, modes.classes
    t_std = float(np.mean(fit.frequency_std_hz[list(cls.tilt)]))
    hidden = modes.split_std_hz if modes.split_std_hz is not None else math.sqrt(2.0) * t_std
    if not (modes.pair_resolved and cls.by_shape and len(cls.tilt) == 2):
        return equal_rollers(rig, k_eq.value_n_per_m, k_eq.std_n_per_m, hidden)
    if blow_dependent:
        warnings.append("per-roller stiffnesses not solved: the blows move the contact modes materially, the tilt "
                        "pair by other amounts than the bounce; equal rollers assumed until the blows are softer")
        return equal_rollers(rig, k_eq.value_n_per_m, k_eq.std_n_per_m, hidden)
    b, (t1, t2) = cls.bounce, cls.tilt
    idx = [b, t1, t2]
    split_std = None
    fc = fit.force_covariance
    if fc is not None and np.all(np.isfinite(fc)):  # the force noise moves both tilt poles alike
        force_var = np.diag(fc)[0::2]
        response_var = np.clip(fit.frequency_std_hz**2 - force_var, 0.0, None)
        split_std = math.sqrt(max(response_var[t1] + response_var[t2] + fc[2 * t1, 2 * t1] + fc[2 * t2, 2 * t2]
                                  - 2.0 * fc[2 * t1, 2 * t2], 0.0))
    try:
        out = solve_rollers(rig, names, live, fit.frequencies_hz[idx], fit.frequency_std_hz[idx],
                            fit.constants[[t1, t2]], None if fit.constants_std is None else fit.constants_std[[t1, t2]],
                            k_eq.value_n_per_m, split_std)
    except (ModelDomainError, np.linalg.LinAlgError, ValueError) as exc:
        warnings.append(f"per-roller stiffness not solved ({exc}): equal rollers assumed")
        return equal_rollers(rig, k_eq.value_n_per_m, k_eq.std_n_per_m, math.sqrt(2.0) * t_std)
    values = np.asarray(out.values_n_per_m, float)
    off = out.mean_n_per_m / k_eq.value_n_per_m - 1.0
    if not (np.all(values > 0) and values.max() <= MAX_ROLLER_RATIO * values.min() and abs(off) <= MAX_MEAN_SHIFT):
        warnings.append(f"per-roller solution not credible (mean {100 * off:+.1f} % from the bounce's equal-roller "
                        f"value, rollers {', '.join(f'{v:.3g}' for v in values)} N/m): equal rollers assumed — "
                        "the tilt pair may be moved by the blows or misassigned")
        return equal_rollers(rig, k_eq.value_n_per_m, k_eq.std_n_per_m, math.sqrt(2.0) * t_std)
    limit = -ndtri(DIFFER_LEVEL / 2)
    split_hz = float(abs(fit.frequencies_hz[t2] - fit.frequencies_hz[t1]))
    hidden = [i for i in range(3) if abs(out.z_symmetric[i]) > limit and i not in out.differing]
    # A split the rig's usual asymmetry explains is no news (the σ holds it); one it explains only rarely is
    unusual = out.asymmetry_equivalent > rig.uncertainty.inertia_asymmetry_rel * UNUSUAL_ASYMMETRY
    if hidden and not out.differing and unusual:
        mean = out.mean_n_per_m
        parts = ", ".join(f"roller {i + 1} {100 * (out.values_n_per_m[i] / mean - 1):+.1f} % (z {out.z[i]:+.1f}; "
                          f"{out.z_symmetric[i]:+.1f} on symmetric discs)" for i in hidden)
        warnings.append(f"roller or rig asymmetry, the data cannot tell: the tilt split {split_hz:.2f} Hz "
                        f"would mean {parts} from their mean, or discs whose inertias about two diameters differ by "
                        f"{100 * out.asymmetry_equivalent:.1f} % (the rig file allows "
                        f"{100 * rig.uncertainty.inertia_asymmetry_rel:.1f} % at 1 σ); the rollers' σ covers both. "
                        "A rig calibrated with equal elements (balls: its own split) tells them apart")
    if out.differing:
        mean = out.mean_n_per_m
        worst = max(out.differing, key=lambda i: abs(out.z[i]))
        parts = ", ".join(f"roller {i + 1} at {math.degrees(rig.contact_angles_rad[i]):.0f}° "
                          f"{100 * (out.values_n_per_m[i] / mean - 1):+.1f} % (z {out.z[i]:+.1f})"
                          for i in sorted(out.differing, key=lambda i: -abs(out.z[i])))
        warnings.append(f"roller stiffnesses differ beyond their uncertainty (test at level {DIFFER_LEVEL:g}): "
                        f"{parts} from their mean; check how roller {worst + 1} is seated")
    return out
