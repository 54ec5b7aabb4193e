"""The blind generator's rig: the paper rig's numbers (read with tomllib) and the 6-DOF rigid-disc eigen-model.

Upper and lower disc each move in z and tilt about x and y; three roller paths (k_i in series with K_setup/3)
join them and a ring support carries the lower disc. Eq. 4 is here only as the closed-form check of the model.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import linalg

PAPER_RIG = Path(__file__).resolve().parents[2] / "labctl" / "data" / "rigs" / "paper_rig.toml"

@dataclass(frozen=True)
class Sensor:
    """One tri-axial accelerometer: on which disc, where (cylindrical), SI."""

    name: str
    disc: str
    radius_m: float
    angle_rad: float


@dataclass(frozen=True)
class Rig:
    """The generator's own rig numbers (SI): what the matched rig file states, plus the hammer point."""

    upper_mass_kg: float
    lower_mass_kg: float
    upper_inertia_kg_m2: float  # mean over the two diameters; the asymmetry is a Case knob
    lower_inertia_kg_m2: float
    upper_thickness_m: float
    lower_thickness_m: float
    contact_radius_m: float
    contact_angles_rad: tuple[float, ...]
    setup_stiffness_n_per_m: float
    support_stiffness_n_per_m: float
    support_radius_m: float
    support_damping_ratio: float
    hammer_radius_m: float
    hammer_angle_rad: float
    sensors: tuple[Sensor, ...]
    paper_toml: dict = field(default_factory=dict, compare=False, repr=False)


def paper_rig(path: Path = PAPER_RIG) -> Rig:
    """The paper rig's numbers, read from its TOML with tomllib (mm, deg converted to SI here)."""
    doc = tomllib.loads(path.read_text())
    up, lo, c, s, h = doc["upper_disc"], doc["lower_disc"], doc["contacts"], doc["support"], doc["hammer"]
    return Rig(
        upper_mass_kg=up["mass_kg"], lower_mass_kg=lo["mass_kg"],
        upper_inertia_kg_m2=up["inertia_kg_m2"], lower_inertia_kg_m2=lo["inertia_kg_m2"],
        upper_thickness_m=up["thickness_mm"] * 1e-3, lower_thickness_m=lo["thickness_mm"] * 1e-3,
        contact_radius_m=c["radius_mm"] * 1e-3, contact_angles_rad=tuple(np.radians(c["angles_deg"]).tolist()),
        setup_stiffness_n_per_m=c["setup_stiffness_n_per_m"],
        support_stiffness_n_per_m=s["stiffness_n_per_m"], support_radius_m=s["radius_mm"] * 1e-3,
        support_damping_ratio=s["damping_ratio"],
        hammer_radius_m=h["radius_mm"] * 1e-3, hammer_angle_rad=float(np.radians(h["angle_deg"])),
        sensors=tuple(Sensor(e["name"], e["disc"], e["radius_mm"] * 1e-3, float(np.radians(e["angle_deg"])))
                      for e in doc["sensors"]),
        paper_toml=doc,
    )


def eq4_bounce_hz(k_n_per_m: float, rig: Rig) -> float:
    """Eq. 4 of the paper: ω0² = 2·K_total/m, 1/K_total = 1/(3k) + 1/K_setup (equal discs, equal rollers)."""
    k_total = 1.0 / (1.0 / (3.0 * k_n_per_m) + 1.0 / rig.setup_stiffness_n_per_m)
    return float(np.sqrt(2.0 * k_total / rig.upper_mass_kg) / (2 * np.pi))


def eq4_stiffness(bounce_hz: float, rig: Rig) -> float:
    """The roller stiffness k that Eq. 4 gives for a bounce frequency (the inverse of eq4_bounce_hz)."""
    k_total = (2 * np.pi * bounce_hz) ** 2 * rig.upper_mass_kg / 2.0
    return float(1.0 / (3.0 * (1.0 / k_total - 1.0 / rig.setup_stiffness_n_per_m)))


@dataclass(frozen=True)
class Model:
    """The 6-DOF rigid-disc model [z, θx, θy] upper then lower; w = z + θx·y − θy·x at (x, y)."""

    mass: np.ndarray
    stiffness: np.ndarray
    freqs_hz: np.ndarray  # ascending
    shapes: np.ndarray  # mass-normalised columns
    contact_modes: tuple[int, ...]  # the three modes that strain the rollers, ascending
    bounce: int
    tilts: tuple[int, int]
    path_stiffness_n_per_m: np.ndarray  # k_i in series with K_setup/3


def _disc_mass(m: float, inertia_xy: np.ndarray, com_xy: np.ndarray) -> np.ndarray:
    """3×3 mass matrix of a rigid disc about its axis: the CM's vertical velocity is ż + ey·θ̇x − ex·θ̇y."""
    a = np.array([1.0, com_xy[1], -com_xy[0]])
    out = m * np.outer(a, a)
    out[1:, 1:] += inertia_xy
    return out


def build_model(rig: Rig, k_n_per_m: np.ndarray, inertia_eps: float = 0.0, axis_rad: float = 0.0,
                com_xy_m: tuple[float, float] = (0.0, 0.0)) -> Model:
    """Assemble M and K, solve the generalized eigenproblem and name the bounce and tilt modes."""
    c, s = np.cos(axis_rad), np.sin(axis_rad)
    rot = np.array([[c, -s], [s, c]])
    i_up = rig.upper_inertia_kg_m2 * rot @ np.diag([1 + inertia_eps, 1 - inertia_eps]) @ rot.T
    mass = linalg.block_diag(_disc_mass(rig.upper_mass_kg, i_up, np.asarray(com_xy_m)),
                             _disc_mass(rig.lower_mass_kg, rig.lower_inertia_kg_m2 * np.eye(2), np.zeros(2)))
    ang = np.asarray(rig.contact_angles_rad)
    x, y = rig.contact_radius_m * np.cos(ang), rig.contact_radius_m * np.sin(ang)
    rows = np.stack([np.ones(3), y, -x, -np.ones(3), -y, x], axis=1)  # roller compression per DOF
    k_path = 1.0 / (1.0 / np.asarray(k_n_per_m, float) + 3.0 / rig.setup_stiffness_n_per_m)
    ks, rs = rig.support_stiffness_n_per_m, rig.support_radius_m
    stiff = rows.T @ (k_path[:, None] * rows) + np.diag([0, 0, 0, ks, ks * rs**2 / 2, ks * rs**2 / 2])
    lam, phi = linalg.eigh(stiff, mass)
    rel = rows @ phi  # roller compressions per mode
    # the share of each mode's strain energy that sits in the rollers (ω² is the whole, mass-normalised)
    share = (k_path[:, None] * rel**2).sum(axis=0) / np.maximum(lam, 1e-9 * lam.max())
    contact = tuple(sorted(np.argsort(share)[-3:].tolist()))
    bounce_share = rel.mean(axis=0) ** 2 / (rel**2).mean(axis=0)
    bounce = max(contact, key=lambda r: bounce_share[r])
    tilts = tuple(r for r in contact if r != bounce)
    return Model(mass, stiff, np.sqrt(np.clip(lam, 0.0, None)) / (2 * np.pi), phi, contact, bounce, tilts, k_path)


def main() -> None:
    """Print the paper rig's eigen-frequencies at the type-1 440 N stiffness and at the brief's 6.6e8 N/m."""
    rig = paper_rig()
    for k in (eq4_stiffness(748.0, rig), 6.6e8):
        m = build_model(rig, np.full(3, k))
        tilt = "/".join(f"{f:.2f}" for f in m.freqs_hz[list(m.tilts)])
        support = "/".join(f"{m.freqs_hz[r]:.1f}" for r in range(6) if r not in m.contact_modes)
        print(f"k {k:.4g} N/m: bounce {m.freqs_hz[m.bounce]:.2f} Hz (Eq. 4: {eq4_bounce_hz(k, rig):.2f}), "
              f"tilt {tilt} Hz, support {support} Hz")


if __name__ == "__main__":
    main()
