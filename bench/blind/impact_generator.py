"""Blind impact generator for the two-disc rig: hammer blows on a 6-DOF rigid-disc model, sampled like a DAQ.

Written without reading labctl's processing or simulator, so its files can judge `labctl identify`: each
`.npz` (the impacts NPZ contract) comes with a `.json` truth (roller stiffnesses, the eigen-solution's bounce
and tilt frequencies, the disturbances drawn) and a matched rig TOML in the paper rig's format.

    python bench/blind/impact_generator.py --out DIR --preset unequal_15 --seeds 3
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
from blind_rig import Model, Rig, build_model, eq4_bounce_hz, eq4_stiffness, paper_rig

AXES = "XYZ"
BOUNCE_440N_HZ = 748.0  # the paper's measured type-1 bounce at 440 N: it fixes the default roller stiffness


@dataclass(frozen=True)
class Case:
    """The knobs of one family of files; (lo, hi) pairs are drawn uniformly per file (per impact where said)."""

    name: str = "equal"
    stiffness_n_per_m: float | None = None  # None: the type-1 stiffness at 440 N (Eq. 4 at 748 Hz, paper rig)
    roller_factors: tuple[float, float, float] = (1.0, 1.0, 1.0)
    permute_rollers: bool = False  # a random permutation of roller_factors per file
    tilt_split_hz: tuple[float, float] = (0.0, 0.0)  # target tilt split from the upper disc's Ixx ≠ Iyy alone
    com_offset_m: float = 0.0  # upper disc's centre of mass off its axis, random direction
    damping_ratio: tuple[float, float] = (0.01, 0.03)  # modal damping of the three contact modes
    transverse: tuple[float, float] = (0.0, 0.0)  # transverse sensitivity per axis, random direction
    mounting_error_deg: float = 0.0  # each sensor's frame tilted by up to this, random axis
    sensitivity_error: float = 0.0  # each axis's gain off by up to ± this fraction
    pulse_width_s: tuple[float, float] = (0.2e-3, 0.5e-3)
    pulse_power: tuple[float, float] = (1.0, 3.0)  # the pulse is sin^p over its width
    peak_force_n: tuple[float, float] = (100.0, 600.0)
    blow_scatter: float = 0.08  # per impact: peak and width vary by up to ± this fraction
    hammer_scatter_m: float = 1.0e-3  # per impact: 1-σ of the hammer point, each in-plane direction
    snr_db: tuple[float, float] = (30.0, 50.0)  # response RMS over its decay to the noise floor
    force_snr_db: tuple[float, float] = (40.0, 60.0)  # force peak to noise
    impacts: int = 3
    fs_hz: float = 20480.0
    samples: int = 65536
    pretrigger_samples: int = 512
    oversample: int = 16  # the force pulse is built on a grid this much finer than fs
    sensor_height_m: float = 0.007  # seismic centre of a sensor above (A4: below) its mounting face
    z_along_blow: bool = False  # False: every Z axis points up (the blow is -Z); True: down


_NOISY = Case()
_TRANSVERSE = dict(transverse=(0.02, 0.03), mounting_error_deg=2.0, sensitivity_error=0.02)
_UNEQUAL = dict(roller_factors=(1.15, 1.00, 0.85), permute_rollers=True)
PRESETS: dict[str, Case] = {
    "clean_440n": replace(_NOISY, name="clean_440n", damping_ratio=(0.018, 0.018), snr_db=(70.0, 70.0),
                          force_snr_db=(70.0, 70.0), peak_force_n=(300.0, 300.0), hammer_scatter_m=0.0),
    "equal": replace(_NOISY, name="equal"),
    "unequal_15": replace(_NOISY, name="unequal_15", **_UNEQUAL),
    "asym_small": replace(_NOISY, name="asym_small", tilt_split_hz=(1.0, 3.0), com_offset_m=1.0e-3),
    "asym_large": replace(_NOISY, name="asym_large", tilt_split_hz=(7.0, 9.0), com_offset_m=1.0e-3),
    "transverse": replace(_NOISY, name="transverse", **_TRANSVERSE),
    "unequal_transverse": replace(_NOISY, name="unequal_transverse", **_UNEQUAL, **_TRANSVERSE),
    "unequal_asym": replace(_NOISY, name="unequal_asym", **_UNEQUAL, tilt_split_hz=(7.0, 9.0),
                            com_offset_m=1.0e-3, **_TRANSVERSE),
    "low_snr": replace(_NOISY, name="low_snr", snr_db=(30.0, 32.0), force_snr_db=(40.0, 42.0)),
}


def sensor_matrix(rig: Rig, case: Case, frames: np.ndarray) -> np.ndarray:
    """(channels × 6) map from DOF accelerations to the channels' readings, given each axis's gain vector.

    frames: (sensors, 3 axes, 3) — each axis's sensitivity vector in the rig frame (gain, direction and
    transverse pickup folded in). A point (x, y, h) moves by (θy·h, −θx·h, z + θx·y − θy·x).
    """
    out = []
    for n, sen in enumerate(rig.sensors):
        upper = sen.disc == "upper"
        th = rig.upper_thickness_m if upper else rig.lower_thickness_m
        h = (th / 2 + case.sensor_height_m) * (1 if upper else -1)
        px, py = sen.radius_m * np.cos(sen.angle_rad), sen.radius_m * np.sin(sen.angle_rad)
        j3 = np.array([[0, 0, h], [0, -h, 0], [1, py, -px]])
        jac = np.hstack([j3, np.zeros((3, 3))]) if upper else np.hstack([np.zeros((3, 3)), j3])
        out.append(frames[n] @ jac)
    return np.vstack(out)


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues rotation about a unit axis."""
    kx = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx


def draw_frames(rig: Rig, case: Case, rng: np.random.Generator) -> tuple[np.ndarray, dict]:
    """Each sensor's axes: nominal X radial, Y tangential, Z vertical; then mounting, gain and transverse errors."""
    frames, info = [], {}
    zsign = -1.0 if case.z_along_blow else 1.0
    for sen in rig.sensors:
        c, s = np.cos(sen.angle_rad), np.sin(sen.angle_rad)
        nominal = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, zsign]])
        axis = rng.normal(size=3)
        tilt = np.radians(rng.uniform(0, case.mounting_error_deg))
        mount = _rotation(axis / np.linalg.norm(axis), tilt)
        gains = 1 + rng.uniform(-case.sensitivity_error, case.sensitivity_error, 3)
        trans = rng.uniform(*case.transverse, 3)
        beta = rng.uniform(0, 2 * np.pi, 3)
        rows = []
        for a in range(3):
            e1, e2 = nominal[(a + 1) % 3], nominal[(a + 2) % 3]
            pick = np.cos(beta[a]) * e1 + np.sin(beta[a]) * e2
            rows.append(gains[a] * mount @ (nominal[a] + trans[a] * pick))
            info[sen.name + AXES[a]] = {"gain": float(gains[a]), "transverse": float(trans[a]),
                                       "transverse_angle_deg": float(np.degrees(beta[a]))}
        info[sen.name] = {"mounting_error_deg": float(np.degrees(tilt))}
        frames.append(np.array(rows))
    return np.array(frames), info


def daq_filter(f_hz: np.ndarray, fs_hz: float) -> np.ndarray:
    """A DAQ's linear-phase anti-alias filter: flat to 0.45·fs, raised-cosine to zero at 0.55·fs."""
    x = np.clip((f_hz - 0.45 * fs_hz) / (0.1 * fs_hz), 0.0, 1.0)
    return 0.5 * (1 + np.cos(np.pi * x))


def _pulse(t: np.ndarray, t0: float, width: float, peak: float, power: float) -> np.ndarray:
    """sin^p force pulse starting at t0 (s), zero outside [t0, t0 + width]."""
    u = np.clip((t - t0) / width, 0.0, 1.0)
    return peak * np.sin(np.pi * u) ** power


def _synthesise(case: Case, model: Model, damping: np.ndarray, sens: np.ndarray, q_hammer: np.ndarray,
                t0: float, width: float, peak: float, power: float) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free force and accelerations of one blow, as a DAQ samples them (anti-alias filter, aliasing kept).

    The pulse is built on a grid `oversample` times finer than fs over twice the record (no wrap-around);
    the response is the modal sum in the frequency domain; bins above fs/2 that pass the filter fold back.
    """
    fs, ov = case.fs_hz, case.oversample
    n_c = 2 * case.samples
    n_f = ov * n_c
    t_f = np.arange(int((t0 + width) * fs * ov) + 2) / (fs * ov)  # the pulse sits at the record's start
    fine = np.zeros(n_f)
    fine[: t_f.size] = _pulse(t_f, t0, width, peak, power)
    k_max = int(0.55 * n_c)
    spec_f = np.fft.rfft(fine)[: k_max + 1]
    f_hz = np.arange(k_max + 1) * fs / n_c
    w = 2 * np.pi * f_hz
    wr = 2 * np.pi * model.freqs_hz
    h = -(w**2) / (wr[:, None] ** 2 - w**2 + 2j * damping[:, None] * wr[:, None] * w)  # (modes × bins)
    weights = (sens @ model.shapes) * (model.shapes.T @ q_hammer)  # (channels × modes)
    y = np.vstack([spec_f, weights @ h * spec_f]) * daq_filter(f_hz, fs)
    z = np.zeros((y.shape[0], n_c), complex)
    z[:, : k_max + 1] += y
    z[:, n_c - np.arange(1, k_max + 1)] += np.conj(y[:, 1:])
    x = np.fft.ifft(z, axis=1).real[:, : case.samples] / ov
    return x[0], x[1:]


def generate(case: Case, seed: int, rig: Rig | None = None) -> tuple[dict, dict]:
    """One file: the impacts NPZ arrays and the truth (deterministic per seed)."""
    rig = rig or paper_rig()
    rng = np.random.default_rng(seed)
    k0 = case.stiffness_n_per_m or eq4_stiffness(BOUNCE_440N_HZ, rig)
    factors = np.asarray(case.roller_factors, float)
    if case.permute_rollers:
        factors = rng.permutation(factors)
    k = k0 * factors
    zeta = rng.uniform(*case.damping_ratio)
    # the inertia asymmetry that splits the tilt pair by the target alone (first order: Δf ≈ f·ε/2)
    sym = build_model(rig, np.full(3, k0))
    f_tilt0 = float(np.mean(sym.freqs_hz[list(sym.tilts)]))
    split_target = rng.uniform(*case.tilt_split_hz)
    eps = 2 * split_target / f_tilt0
    axis = rng.uniform(0, np.pi)
    com_dir = rng.uniform(0, 2 * np.pi)
    com = case.com_offset_m * np.array([np.cos(com_dir), np.sin(com_dir)])
    model = build_model(rig, k, eps, axis, tuple(com))
    damping = np.full(6, rig.support_damping_ratio)
    damping[list(model.contact_modes)] = zeta
    frames, sensor_info = draw_frames(rig, case, rng)
    sens = sensor_matrix(rig, case, frames)
    snr_db, fsnr_db = rng.uniform(*case.snr_db), rng.uniform(*case.force_snr_db)
    width0, peak0, power = rng.uniform(*case.pulse_width_s), rng.uniform(*case.peak_force_n), rng.uniform(
        *case.pulse_power)
    slow = min(model.freqs_hz[r] for r in model.contact_modes)
    window = slice(case.pretrigger_samples, case.pretrigger_samples + int(case.fs_hz / (zeta * 2 * np.pi * slow)))
    z_rows = [i for i, n in enumerate(channel_names(rig)) if n.endswith("Z")]
    forces, accels, blows = [], [], []
    for _ in range(case.impacts):
        width = width0 * (1 + rng.uniform(-case.blow_scatter, case.blow_scatter))
        peak = peak0 * (1 + rng.uniform(-case.blow_scatter, case.blow_scatter))
        t0 = (case.pretrigger_samples + rng.uniform(0, 1)) / case.fs_hz - 0.2 * width  # trigger ~10 % up
        r, ang = rig.hammer_radius_m, rig.hammer_angle_rad
        xh, yh = np.array([r * np.cos(ang), r * np.sin(ang)]) + rng.normal(0, case.hammer_scatter_m, 2)
        q = -np.array([1.0, yh, -xh, 0, 0, 0])  # a downward blow on the upper disc's top face
        force, accel = _synthesise(case, model, damping, sens, q, t0, width, peak, power)
        rms = np.sqrt((accel[z_rows, window] ** 2).mean(axis=1))
        sigma = float(np.median(rms)) * 10 ** (-snr_db / 20)
        sigma_f = float(force.max()) * 10 ** (-fsnr_db / 20)
        chan_snr = 20 * np.log10(np.sqrt((accel[:, window] ** 2).mean(axis=1)) / sigma)
        forces.append(force + rng.normal(0, sigma_f, force.shape))
        accels.append(accel + rng.normal(0, sigma, accel.shape))
        blows.append({"t0_s": float(t0), "width_s": float(width), "peak_n": float(peak), "power": float(power),
                      "x_m": float(xh), "y_m": float(yh), "accel_noise_std": sigma, "force_noise_std": sigma_f,
                      "channel_snr_db": dict(zip(channel_names(rig), np.round(chan_snr, 2).tolist(), strict=True))})
    arrays = {"fs": np.float64(case.fs_hz), "force": np.array(forces), "accel": np.array(accels),
              "channels": np.array(channel_names(rig))}
    truth = _truth(case, seed, rig, model, k, zeta, eps, axis, com, sensor_info, snr_db, fsnr_db, blows)
    return arrays, truth


def channel_names(rig: Rig) -> list[str]:
    """A1X, A1Y, A1Z, ... in the rig's sensor order."""
    return [s.name + a for s in rig.sensors for a in AXES]


def _truth(case: Case, seed: int, rig: Rig, model: Model, k: np.ndarray, zeta: float, eps: float, axis: float,
           com: np.ndarray, sensor_info: dict, snr_db: float, fsnr_db: float, blows: list) -> dict:
    """What the file was made from, for judging: stiffnesses, eigen-solution, disturbances drawn."""
    f = model.freqs_hz
    tilt = sorted(float(f[r]) for r in model.tilts)
    mean_k = float(k.mean())
    i_up = rig.upper_inertia_kg_m2
    return {
        "preset": case.name, "seed": seed, "case": asdict(case),
        "k_n_per_m": k.tolist(), "k_mean_n_per_m": mean_k,
        "path_stiffness_n_per_m": model.path_stiffness_n_per_m.tolist(),
        "rollers_differing_5pct": [i + 1 for i, ki in enumerate(k) if abs(ki / mean_k - 1) > 0.05],
        "bounce_hz": float(f[model.bounce]), "tilt_hz": tilt, "tilt_mean_hz": float(np.mean(tilt)),
        "tilt_split_hz": tilt[1] - tilt[0], "mode_freqs_hz": f.tolist(),
        "support_modes_hz": [float(f[r]) for r in range(6) if r not in model.contact_modes],
        "eq4_bounce_hz_of_mean_k": eq4_bounce_hz(mean_k, rig),
        "damping_ratio": zeta, "support_damping_ratio": rig.support_damping_ratio,
        "inertia_asymmetry": {"eps": eps, "ixx_kg_m2": i_up * (1 + eps), "iyy_kg_m2": i_up * (1 - eps),
                              "principal_axis_deg": float(np.degrees(axis)),
                              "com_offset_m": com.tolist()},
        "sensors": sensor_info, "snr_db": snr_db, "force_snr_db": fsnr_db, "blows": blows,
        "conventions": {"z": "down (along the blow)" if case.z_along_blow else "up (the blow is -Z)",
                        "x": "radial outward", "y": "tangential (counter-clockwise)",
                        "force": "positive pushing into the upper disc", "rollers": "1-3 at the rig's angles"},
    }


def rig_toml(rig: Rig, case: Case, name: str) -> str:
    """The matched rig file (the paper rig's format) holding this generator's own numbers.

    One inertia per disc: the upper disc's mean over its diameters (the asymmetry is in the truth only).
    Tables the generator does not model (uncertainty, loading) are the paper rig's.
    """
    p = rig.paper_toml
    zeta = float(np.mean(case.damping_ratio))

    def table(title: str, values: dict) -> str:
        return f"[{title}]\n" + "".join(f"{k} = {_toml_value(v)}\n" for k, v in values.items()) + "\n"

    out = f'name = "{name}"\n\n'
    out += table("upper_disc", {"mass_kg": rig.upper_mass_kg, "inertia_kg_m2": rig.upper_inertia_kg_m2,
                                "thickness_mm": rig.upper_thickness_m * 1e3})
    out += table("lower_disc", {"mass_kg": rig.lower_mass_kg, "inertia_kg_m2": rig.lower_inertia_kg_m2,
                                "thickness_mm": rig.lower_thickness_m * 1e3})
    out += table("contacts", {"radius_mm": rig.contact_radius_m * 1e3,
                              "angles_deg": [float(np.degrees(a)) for a in rig.contact_angles_rad],
                              "setup_stiffness_n_per_m": rig.setup_stiffness_n_per_m})
    out += table("uncertainty", p["uncertainty"])
    out += table("support", {"stiffness_n_per_m": rig.support_stiffness_n_per_m,
                             "radius_mm": rig.support_radius_m * 1e3, "damping_ratio": rig.support_damping_ratio})
    out += table("damping", {"modal_damping_ratio": zeta})
    out += table("loading", p["loading"])
    hammer_deg = float(np.degrees(rig.hammer_angle_rad))
    out += table("hammer", {"radius_mm": rig.hammer_radius_m * 1e3, "angle_deg": hammer_deg})
    for s in rig.sensors:
        out += table("[sensors]", {"name": s.name, "disc": s.disc, "radius_mm": s.radius_m * 1e3,
                                   "angle_deg": float(np.degrees(s.angle_rad))})
    return out


def _toml_value(v: object) -> str:
    """A TOML literal for the plain values a rig file holds."""
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return repr(round(float(v), 12)) if isinstance(v, float) else str(v)


def write_rig(path: Path, case: Case, rig: Rig | None = None) -> Path:
    """Write the matched rig TOML for a case."""
    rig = rig or paper_rig()
    path.write_text(rig_toml(rig, case, f"blind generator rig ({case.name})"))
    return path


def write_file(out: Path, case: Case, seed: int, rig: Rig | None = None) -> Path:
    """Write STEM.npz, STEM.json and STEM_rig.toml for one seed; return the .npz path."""
    rig = rig or paper_rig()
    stem = out / f"{case.name}_s{seed}"
    arrays, truth = generate(case, seed, rig)
    rig_path = write_rig(out / f"{case.name}_s{seed}_rig.toml", case, rig)
    truth["rig_file"] = rig_path.name
    np.savez(stem.with_suffix(".npz"), **arrays)
    stem.with_suffix(".json").write_text(json.dumps(truth, indent=1))
    return stem.with_suffix(".npz")


def main(argv: list[str] | None = None) -> int:
    """CLI: write --seeds files of one preset into --out."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--preset", default="equal", help="one of: " + ", ".join(PRESETS))
    ap.add_argument("--seeds", type=int, default=3, help="how many files (seeds first-seed, first-seed+1, ...)")
    ap.add_argument("--first-seed", type=int, default=1)
    args = ap.parse_args(argv)
    if args.preset not in PRESETS:
        print(f"--preset = {args.preset!r}: expected one of {', '.join(PRESETS)}", file=sys.stderr)
        return 2
    if args.seeds < 1:
        print(f"--seeds = {args.seeds}: expected a positive integer", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        path = write_file(args.out, PRESETS[args.preset], seed)
        truth = json.loads(path.with_suffix(".json").read_text())
        tilt = "/".join(f"{x:.1f}" for x in truth["tilt_hz"])
        print(f"{path}: bounce {truth['bounce_hz']:.1f} Hz, tilt {tilt} Hz, "
              f"k {', '.join(f'{x:.3g}' for x in truth['k_n_per_m'])} N/m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
