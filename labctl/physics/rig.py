"""Rigid-body dynamics of the two-disc rig: bounce and tilt modes from the roller stiffnesses, and back (Eq. 4).

Each disc moves in vertical translation z and small rotations rx, ry about its centre of mass. Each roller
is a spring k_i in series with its third of the setup compliance (1/K_setup per roller path = 3/K_setup), so
for equal rollers the bounce mode reduces to Eq. 4: ω0² = 2·K_total/m, 1/K_total = 1/(3k) + 1/K_setup.
The lower disc rests on the rubber tube, which gives three slow support modes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg import eigh
from scipy.optimize import brentq

from labctl.errors import ModelDomainError
from labctl.physics.rig_config import RigConfig, Sensor

DOF = ("z_upper", "rx_upper", "ry_upper", "z_lower", "rx_lower", "ry_lower")


def roller_path_stiffness(roller_stiffness_n_per_m: ArrayLike, setup_stiffness_n_per_m: float) -> np.ndarray:
    """Each roller in series with its share of the setup compliance: 1/k_path = 1/k + 3/K_setup."""
    k = np.asarray(roller_stiffness_n_per_m, dtype=float)
    return 1.0 / (1.0 / k + 3.0 / setup_stiffness_n_per_m)


def roller_stiffness_from_path(path_stiffness_n_per_m: ArrayLike, setup_stiffness_n_per_m: float) -> np.ndarray:
    """The inverse of ``roller_path_stiffness``: a roller path's stiffness (a static slope dP/dδ per roller) with
    its share of the setup compliance removed, 1/k = 1/k_path − 3/K_setup; NaN where nothing is left."""
    remaining = 1.0 / np.asarray(path_stiffness_n_per_m, dtype=float) - 3.0 / setup_stiffness_n_per_m
    with np.errstate(divide="ignore"):
        return np.where(remaining > 0, 1.0 / np.where(remaining > 0, remaining, 1.0), np.nan)


def apparent_roller_stiffness(
    roller_stiffness_n_per_m: ArrayLike, true_setup_n_per_m: float, assumed_setup_n_per_m: float
) -> np.ndarray:
    """The roller stiffness Eq. 4 reports when it assumes one K_setup and the rig really has another."""
    k = np.asarray(roller_stiffness_n_per_m, dtype=float)
    return 1.0 / (1.0 / k + 3.0 / true_setup_n_per_m - 3.0 / assumed_setup_n_per_m)


@dataclass(frozen=True)
class RigModes:
    """Modes of the rig for one set of roller stiffnesses; shapes are mass-normalised over DOF."""

    frequencies_hz: np.ndarray
    shapes: np.ndarray  # (6 dof, 6 modes)
    damping_ratios: np.ndarray
    bounce: int
    tilt: tuple[int, int]
    support: tuple[int, int, int]
    config: RigConfig

    @property
    def bounce_hz(self) -> float:
        return float(self.frequencies_hz[self.bounce])

    @property
    def tilt_hz(self) -> tuple[float, float]:
        a, b = sorted(float(self.frequencies_hz[i]) for i in self.tilt)
        return (a, b)

    def displacement_at(self, sensor: Sensor, mode: int) -> np.ndarray:
        """Mode shape at a sensor in its local axes (X radial, Y tangential, Z vertical)."""
        return point_displacement(self.shapes[:, mode], sensor.disc, sensor.x_m, sensor.y_m, sensor.z_m,
                                  sensor.angle_rad)

    def vertical_at(self, disc: str, x_m: float, y_m: float, mode: int) -> float:
        """Vertical mode-shape value at a point of a disc's face (e.g. the hammer's impact point)."""
        return float(point_displacement(self.shapes[:, mode], disc, x_m, y_m, 0.0, 0.0)[2])

    def sensor_shapes(self, mode: int) -> dict[str, float]:
        """Mode shape per channel name (``A1X`` … ``A4Z``)."""
        out: dict[str, float] = {}
        for s in self.config.sensors:
            for ch, v in zip(s.channels, self.displacement_at(s, mode), strict=True):
                out[ch] = float(v)
        return out


def point_displacement(
    shape: np.ndarray, disc: str, x_m: float, y_m: float, z_m: float, angle_rad: float
) -> np.ndarray:
    """Displacement (radial, tangential, vertical) of a point of a disc for a DOF vector (z, rx, ry)."""
    off = 0 if disc == "upper" else 3
    z, rx, ry = shape[off], shape[off + 1], shape[off + 2]
    ux, uy, uz = ry * z_m, -rx * z_m, z + rx * y_m - ry * x_m
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([c * ux + s * uy, -s * ux + c * uy, uz])


def _contact_rows(config: RigConfig) -> np.ndarray:
    """(3, 6) matrix: relative approach of the two discs at each roller per unit DOF."""
    xy = config.contact_xy_m
    rows = np.zeros((len(xy), 6))
    for i, (x, y) in enumerate(xy):
        rows[i] = [1.0, y, -x, -1.0, -y, x]
    return rows


def rig_matrices(config: RigConfig, roller_stiffness_n_per_m: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Stiffness and (diagonal) mass matrices over DOF for three (possibly unequal) roller stiffnesses."""
    k = np.broadcast_to(np.asarray(roller_stiffness_n_per_m, dtype=float), (3,))
    if np.any(~np.isfinite(k)) or np.any(k <= 0):
        raise ModelDomainError(f"roller stiffness must be positive and finite, got {k.tolist()} N/m")
    k_path = roller_path_stiffness(k, config.setup_stiffness_n_per_m)
    rows = _contact_rows(config)
    stiff = rows.T @ np.diag(k_path) @ rows
    ks, rs = config.support_stiffness_n_per_m, config.support_radius_m
    stiff[3, 3] += ks
    stiff[4, 4] += 0.5 * ks * rs**2
    stiff[5, 5] += 0.5 * ks * rs**2
    up, lo = config.upper, config.lower
    mass = np.diag([up.mass_kg, up.inertia_kg_m2, up.inertia_kg_m2, lo.mass_kg, lo.inertia_kg_m2, lo.inertia_kg_m2])
    return stiff, mass


def _bounce_index(approach: np.ndarray) -> np.ndarray:
    """Column of ``approach`` ((..., 3 rollers, modes): roller approaches per mode) whose approaches are most
    alike: the bounce, per leading index."""
    rms = np.sqrt(np.mean(approach**2, axis=-2))
    return np.argmax(np.abs(approach.mean(axis=-2)) / np.where(rms > 0, rms, 1.0), axis=-1)


def rig_modes(config: RigConfig, roller_stiffness_n_per_m: ArrayLike) -> RigModes:
    """Eigen-analysis for three (possibly unequal) roller stiffnesses; one value means all three equal."""
    stiff, mass = rig_matrices(config, roller_stiffness_n_per_m)
    omega2, shapes = eigh(stiff, mass)
    freqs = np.sqrt(np.clip(omega2, 0.0, None)) / (2.0 * math.pi)
    contact_modes = [3, 4, 5]
    bounce = contact_modes[int(_bounce_index(_contact_rows(config) @ shapes[:, contact_modes]))]
    tilt = tuple(m for m in contact_modes if m != bounce)
    damping = np.array([config.support_damping_ratio] * 3 + [config.modal_damping_ratio] * 3)
    return RigModes(freqs, shapes, damping, bounce, (tilt[0], tilt[1]), (0, 1, 2), config)


def bounce_hz(config: RigConfig, roller_stiffness_n_per_m: ArrayLike) -> float:
    """Bounce frequency for the given roller stiffness(es)."""
    return rig_modes(config, roller_stiffness_n_per_m).bounce_hz


def roller_stiffness_from_bounce(config: RigConfig, bounce_frequency_hz: float) -> float:
    """Inverse of the rig model for three equal rollers: the per-roller k that gives this bounce frequency.

    For a rig without support this is Eq. 4 solved for k; the support tube's small share is included.
    """
    f_max = math.sqrt(2.0 * config.setup_stiffness_n_per_m / config.upper.mass_kg) / (2.0 * math.pi)
    if not (math.isfinite(bounce_frequency_hz) and bounce_frequency_hz > 0):
        raise ModelDomainError(f"bounce frequency must be a positive number of Hz, got {bounce_frequency_hz!r}")
    lo_k, hi_k = 1e2, 1e13
    f_lo, f_hi = bounce_hz(config, lo_k), bounce_hz(config, hi_k)
    if not f_lo < bounce_frequency_hz < f_hi:
        raise ModelDomainError(
            f"bounce frequency {bounce_frequency_hz:.6g} Hz is outside what this rig can show "
            f"({f_lo:.4g} to {f_hi:.4g} Hz; the setup stiffness alone limits it to ~{f_max:.4g} Hz)"
        )
    log_k = brentq(lambda lk: bounce_hz(config, 10.0**lk) - bounce_frequency_hz, math.log10(lo_k),
                   math.log10(hi_k), xtol=1e-12, rtol=1e-13)
    return float(10.0**log_k)


@dataclass(frozen=True)
class BounceSensitivity:
    """How the bounce frequency moves with the roller stiffness and the rig parameters (Hz per unit)."""

    per_roller_stiffness: float  # Hz per N/m, all three rollers together
    per_disc_mass: float  # Hz per kg
    per_setup_stiffness: float  # Hz per N/m of K_setup


def bounce_sensitivity(config: RigConfig, roller_stiffness_n_per_m: float) -> BounceSensitivity:
    """Derivatives of the bounce frequency (forward differences of the rig model) for the uncertainty budget."""
    k = float(roller_stiffness_n_per_m)
    h = 1e-5
    f0, f_k = ContactModeModel.of(config).many(np.array([[k] * 3, [k * (1 + h)] * 3]))[0][:, 0]
    dk = float(f_k - f0) / (k * h)
    ks = config.setup_stiffness_n_per_m
    # k and K_setup enter only through the path stiffness 1/(1/k + 3/K_setup): df/dK_setup = df/dk · 3k²/K_setup²;
    # the discs' masses and inertias all scaled by (1 + h) scale every ω² by 1/(1 + h): df/dm = -f/(2m)
    return BounceSensitivity(dk, -0.5 * float(f0) / config.upper.mass_kg, dk * 3.0 * k * k / (ks * ks))


class ContactModeModel:
    """The rig model prepared for many evaluations at different roller stiffnesses (the per-roller inverse):
    the contact geometry, support and mass scaling are computed once; each call is one 6 × 6 eigenproblem."""

    _prepared: dict[int, ContactModeModel] = {}

    @classmethod
    def of(cls, config: RigConfig) -> ContactModeModel:
        """The model prepared for ``config``, made once per rig object (a processing run asks for it at every
        step); a small cache keyed by the object's identity."""
        model = cls._prepared.get(id(config))
        if model is None or model.config is not config:
            if len(cls._prepared) >= 16:
                cls._prepared.clear()
            model = cls._prepared[id(config)] = cls(config)
        return model

    def __init__(self, config: RigConfig) -> None:
        self.config = config
        self.rows = _contact_rows(config)
        base, mass = rig_matrices(config, 1e300)  # rollers' share vanishes (1/k_path → 3/K_setup aside)
        k_path0 = roller_path_stiffness(np.full(3, 1e300), config.setup_stiffness_n_per_m)
        self.support = base - self.rows.T @ np.diag(k_path0) @ self.rows
        self.scale = 1.0 / np.sqrt(np.diag(mass))
        self.outer = np.outer(self.scale, self.scale)
        self.inv_setup = 3.0 / config.setup_stiffness_n_per_m
        self.row_outer = np.einsum("ci,cj->cij", self.rows, self.rows).reshape(len(self.rows), 36)

    def __call__(self, roller_stiffness_n_per_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(bounce, lower tilt, upper tilt) frequencies (Hz) and their DOF shapes (6, 3)."""
        freqs, shapes = self.many(np.asarray(roller_stiffness_n_per_m, dtype=float)[None, :])
        return freqs[0], shapes[0]

    def many(self, roller_stiffness_n_per_m: np.ndarray,
             asymmetry: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The same for n sets of three stiffnesses (n, 3) at once: frequencies (n, 3), shapes (n, 6, 3).

        ``asymmetry`` (n, 2): the discs' inertia asymmetry (u, v) = (I1 - I2)/I · (cos 2φ, sin 2φ), carried by the
        upper disc (both discs tilt together in the contact modes: their asymmetries act alike on the tilt pair);
        None: symmetric discs, as the rig file describes them."""
        k = np.asarray(roller_stiffness_n_per_m, dtype=float)
        if np.any(~np.isfinite(k)) or np.any(k <= 0):
            raise ModelDomainError(f"roller stiffness must be positive and finite, got {k.tolist()} N/m")
        k_path = 1.0 / (1.0 / k + self.inv_setup)
        stiff = self.support + (k_path @ self.row_outer).reshape(-1, 6, 6)
        if asymmetry is None:
            omega2, v = np.linalg.eigh(stiff * self.outer)
            shapes = v[:, :, 3:] * self.scale[None, :, None]
        else:
            scale = _inverse_sqrt_mass(self.scale, np.asarray(asymmetry, dtype=float).reshape(len(k), 2))
            omega2, v = np.linalg.eigh(scale @ stiff @ scale)
            shapes = (scale @ v)[:, :, 3:]
        freqs = np.sqrt(np.clip(omega2[:, 3:], 0.0, None)) / (2.0 * math.pi)
        b = _bounce_index(self.rows @ shapes)
        others = np.array([[1, 2], [0, 2], [0, 1]])[b]
        rows = np.arange(len(k))
        swap = freqs[rows, others[:, 0]] > freqs[rows, others[:, 1]]
        others[swap] = others[swap][:, ::-1]
        order = np.column_stack([b, others])
        return np.take_along_axis(freqs, order, axis=1), np.take_along_axis(shapes, order[:, None, :], axis=2)


def _inverse_sqrt_mass(scale: np.ndarray, asymmetry: np.ndarray) -> np.ndarray:
    """(n, 6, 6) M^(-1/2) of the rig's mass matrix (diagonal ``scale`` = 1/sqrt(m)) with the upper disc's
    rotational block I·(1 + ½[[u, v], [v, -u]]): its eigenvalues are I(1 ± r/2), r = |(u, v)|, so its inverse
    square root is a·1 + b·R with R = [[u, v], [v, -u]]/r and a, b from (1 ± r/2)^(-1/2)."""
    u, v = asymmetry[:, 0], asymmetry[:, 1]
    r = np.hypot(u, v)
    if np.any(r >= 2.0):
        raise ModelDomainError(f"inertia asymmetry {float(r.max()):.3g} leaves a principal inertia ≤ 0")
    hi, lo = (1.0 + 0.5 * r) ** -0.5, (1.0 - 0.5 * r) ** -0.5
    a, b = 0.5 * (hi + lo), 0.5 * (hi - lo)
    safe = np.where(r > 0, r, 1.0)
    out = np.repeat(np.diag(scale)[None], len(u), axis=0)
    s = scale[1]  # the upper disc's 1/sqrt(I)
    out[:, 1, 1] = s * (a + b * u / safe)
    out[:, 2, 2] = s * (a - b * u / safe)
    out[:, 1, 2] = out[:, 2, 1] = s * b * v / safe
    return out


def contact_modes(config: RigConfig, roller_stiffness_n_per_m: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """(bounce, lower tilt, upper tilt) frequencies (Hz) and their DOF shapes (6, 3) for three roller
    stiffnesses (the same model as ``rig_modes``)."""
    k = np.broadcast_to(np.asarray(roller_stiffness_n_per_m, dtype=float), (3,))
    return ContactModeModel.of(config)(k)


def contact_modes_hz(config: RigConfig, roller_stiffness_n_per_m: ArrayLike) -> tuple[float, float, float]:
    """(bounce, lower tilt, upper tilt) frequencies for three roller stiffnesses."""
    f, _ = contact_modes(config, roller_stiffness_n_per_m)
    return float(f[0]), float(f[1]), float(f[2])


def equal_roller_stiffness(config: RigConfig, bounce_frequency_hz: float) -> tuple[float, float]:
    """(k, df/dk): the per-roller stiffness of three equal rollers that gives this bounce frequency, by Newton
    steps on ln k from Eq. 4 (the support's small share then included), and the slope there (Hz per N/m).
    Falls back to ``roller_stiffness_from_bounce`` (bracketing) when Newton does not settle."""
    m = ContactModeModel.of(config)
    mass = config.upper.mass_kg
    w2 = (2.0 * math.pi * bounce_frequency_hz) ** 2
    inv = 2.0 / (mass * w2) - 1.0 / config.setup_stiffness_n_per_m  # Eq. 4: 1/(3k) = 2/(m ω²) - 1/K_setup
    k = 1.0 / (3.0 * inv) if inv > 0 else roller_stiffness_from_bounce(config, bounce_frequency_hz)
    for _ in range(8):
        dk = 1e-6 * k
        f0, f1 = (float(v) for v in m.many(np.array([[k] * 3, [k + dk] * 3]))[0][:, 0])
        slope = (f1 - f0) / dk
        if not slope > 0:
            break
        step = (bounce_frequency_hz - f0) / slope
        k = max(k + step, 0.5 * k)
        if abs(step) < 1e-12 * k:
            return k, slope
    k = roller_stiffness_from_bounce(config, bounce_frequency_hz)
    dk = 1e-6 * k
    return k, (bounce_hz(config, k + dk) - bounce_hz(config, k)) / dk
