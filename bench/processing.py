"""Benchmark: labctl's modal processing against pyFRF + sdypy-EMA, the bare rfft and the Cramér–Rao bound.

Run by hand, never in CI (the peers are bench-only installs, not labctl dependencies)::

    pip install pyfrf sdypy-ema
    python bench/processing.py [--seeds 20] [--quick]

Every case synthesises impact sets with known truth (tests/synth_impacts.py: modal superposition of the
rig's modes, bounce 745 Hz, tilt pair 580/582 Hz, ζ 0.018, 3 impacts × 65 536 samples at 20 480 Hz, noise at
the given SNR) and runs, in this one process and on the same arrays:

* ours: ``labctl.processing.identify`` (checks, windows, H1, mode fit, stiffness: the whole step);
* pyFRF (H1 + coherence, force and exponential windows, ``is_data_ok`` per impact) followed by sdypy-EMA
  (LSCF poles, ``select_closest_poles`` at the nominal frequencies), as their documentation shows;
* the floor: ``numpy.fft.rfft`` of the same force and response arrays, nothing else;
* the Cramér–Rao bound of the bounce frequency for the same signal model (force known, white noise).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import math
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from labctl.physics import RigConfig, load_rig  # noqa: E402
from labctl.physics.rig_config import Sensor  # noqa: E402
from labctl.processing import check_impact, identify  # noqa: E402
from tests.synth_impacts import SynthMode, paper_case_modes, synth_impacts  # noqa: E402

BOUNCE_HZ, TILT_HZ, ZETA = 745.0, (580.0, 582.0), 0.018
ACCEL_RANGE = 50 * 9.80665  # ±50 g accelerometers
FORCE_RANGE = 2224.0  # PCB 086D05
CHANNEL_SETS = {
    1: ("A1Z",),
    3: ("A1Z", "A2Z", "A3Z"),
    6: ("A1Z", "A2Z", "A3Z", "A4Z", "A1X", "A2Y"),
}


def bench_rig(n_channels: int) -> tuple[RigConfig, tuple[str, ...]]:
    """The paper's rig (or, for 24 channels, the same rig with four more tri-axial sensors)."""
    rig = load_rig()
    if n_channels in CHANNEL_SETS:
        return rig, CHANNEL_SETS[n_channels]
    if n_channels == 12:
        return rig, rig.channels
    up, lo = 0.5 * rig.upper.thickness_m, -0.5 * rig.lower.thickness_m
    extra = tuple(
        Sensor(f"A{5 + i}", disc, 0.08 * math.cos(a), 0.08 * math.sin(a), z, a)
        for i, (disc, a, z) in enumerate([("upper", math.radians(60), up), ("upper", math.radians(180), up),
                                          ("upper", math.radians(300), up), ("lower", 0.0, lo)])
    )
    wide = dataclasses.replace(rig, sensors=rig.sensors + extra)
    return wide, wide.channels


def crlb_hz(modes: list[SynthMode], force_n: np.ndarray, fs_hz: float, sigma: float) -> dict[str, float]:
    """Cramér–Rao bound (1 σ) of each contact mode's frequency: force known, white response noise σ.

    Parameters: frequency, damping and a real modal constant per channel for the bounce and both tilt
    modes; the other modes are known. Fisher information summed over all lines and impacts of the record.
    """
    n = force_n.shape[-1]
    spec = np.fft.rfft(force_n, axis=-1)[:, 1:n // 2]
    f = np.fft.rfftfreq(n, 1.0 / fs_hz)[1:n // 2]
    weight = np.sqrt(np.sum(np.abs(spec) ** 2, axis=0))
    s = 2j * np.pi * f
    contact = [m for m in modes if m.kind in ("bounce", "tilt")]
    n_m, n_ch = len(contact), len(contact[0].residue)
    basis, d_f, d_z = [], [], []
    for m in contact:
        w = 2 * np.pi * m.frequency_hz
        den = s**2 + 2 * m.damping_ratio * w * s + w**2
        basis.append(s**2 / den)
        d_f.append(-(s**2) * (2 * m.damping_ratio * s + 2 * w) / den**2 * 2 * np.pi)
        d_z.append(-(s**2) * (2 * w * s) / den**2)
    n_p = 2 * n_m + n_m * n_ch
    fim = np.zeros((n_p, n_p))
    for c in range(n_ch):
        jac = np.zeros((n_p, len(f)), dtype=complex)
        for r, m in enumerate(contact):
            jac[2 * r] = m.residue[c] * d_f[r]
            jac[2 * r + 1] = m.residue[c] * d_z[r]
            jac[2 * n_m + r * n_ch + c] = basis[r]
        jac *= weight
        fim += 2.0 * np.real(jac.conj() @ jac.T) / (n * sigma**2)
    cov = np.linalg.pinv(fim)
    out: dict[str, float] = {}
    for r, m in enumerate(contact):
        key = m.kind if m.kind == "bounce" else f"tilt{r}"
        out[key] = math.sqrt(cov[2 * r, 2 * r])
    return out


def run_ours(s, rig: RigConfig) -> dict:
    t0 = time.perf_counter()
    r = identify(s.force_n, s.accel_m_per_s2, s.fs_hz, s.channels, rig, accel_ranges=ACCEL_RANGE,
                 force_range_n=FORCE_RANGE)
    dt = time.perf_counter() - t0
    return {"time": dt, "bounce": r.bounce_hz, "tilt": r.tilt_hz, "zeta": r.bounce_damping_ratio}


def run_floor(s) -> float:
    t0 = time.perf_counter()
    np.fft.rfft(s.accel_m_per_s2, axis=-1)
    np.fft.rfft(s.force_n, axis=-1)
    return time.perf_counter() - t0


def run_peers(s) -> dict:
    import pyFRF
    from sdypy import EMA

    t0 = time.perf_counter()
    ok = []
    frf = pyFRF.FRF(int(round(s.fs_hz)), exc=s.force_n, resp=s.accel_m_per_s2,
                    window=("force:0.01", "exponential:0.01"), frf_estimator="H1")
    for i in range(len(s.force_n)):
        ok.append(bool(frf.is_data_ok(s.force_n[i][None, None], s.accel_m_per_s2[i][None])))
    h1 = frf.get_FRF(frf_form="accelerance")[:, 0, 1:]  # the 0 Hz line is undefined for accelerance
    frf.get_coherence()
    f = frf.get_f_axis()[1:]
    t1 = time.perf_counter()
    result = {"time_pyfrf": t1 - t0, "ok": ok}
    try:
        with warnings.catch_warnings(), contextlib.redirect_stderr(io.StringIO()):
            warnings.simplefilter("ignore")
            model = EMA.Model(frf=h1, freq=f, lower=400, upper=1000, pol_order_high=60, frf_form="accelerance")
            model.get_poles(method="lscf", show_progress=False)
            model.select_closest_poles([TILT_HZ[0], TILT_HZ[1], BOUNCE_HZ])
        freqs, zetas = np.asarray(model.nat_freq, float), np.asarray(model.nat_xi, float)
        result.update(bounce=float(freqs[2]), tilt=(float(freqs[0]), float(freqs[1])), zeta=float(zetas[2]))
    except Exception as exc:  # the peer failing is a result too
        result.update(bounce=math.nan, tilt=(math.nan, math.nan), zeta=math.nan, error=type(exc).__name__)
    result["time_ema"] = time.perf_counter() - t1
    return result


def pair_ok(tilt: tuple[float, float]) -> bool:
    a, b = sorted(tilt)
    return abs(a - TILT_HZ[0]) < 0.3 and abs(b - TILT_HZ[1]) < 0.3


def run_case(snr_db: float, n_channels: int, seeds: int, peers: bool) -> dict:
    rig, channels = bench_rig(n_channels)
    modes = paper_case_modes(BOUNCE_HZ, TILT_HZ, ZETA, rig=rig, channels=channels)
    rows = []
    bound = None
    for seed in range(seeds):
        s = synth_impacts(modes, channels, snr_db=snr_db, seed=1000 + seed)
        if bound is None:
            bound = crlb_hz(modes, s.force_n, s.fs_hz, s.truth["noise_m_per_s2"])
            run_ours(s, rig)  # warm caches once
        row = {"ours": run_ours(s, rig), "floor": run_floor(s)}
        if peers:
            row["peers"] = run_peers(s)
        rows.append(row)
    ours = [r["ours"] for r in rows]

    def rms(values):
        v = np.asarray(values, float)
        return float(np.sqrt(np.nanmean(v**2))) if np.any(np.isfinite(v)) else math.nan

    out = {
        "snr": snr_db, "channels": n_channels, "crlb": bound["bounce"],
        "ours_err": rms([o["bounce"] - BOUNCE_HZ for o in ours]),
        "ours_pair": float(np.mean([pair_ok(o["tilt"]) for o in ours])),
        "ours_zeta": float(np.mean([o["zeta"] / ZETA - 1 for o in ours])),
        "ours_zeta_se": float(np.std([o["zeta"] / ZETA - 1 for o in ours], ddof=1) / math.sqrt(seeds)),
        "ours_ms": 1e3 * float(np.median([o["time"] for o in ours])),
        "floor_ms": 1e3 * float(np.median([r["floor"] for r in rows])),
        "ours_best_ms": 1e3 * float(np.min([o["time"] for o in ours])),
        "floor_best_ms": 1e3 * float(np.min([r["floor"] for r in rows])),
    }
    if peers:
        p = [r["peers"] for r in rows]
        out.update({
            "peer_err": rms([q["bounce"] - BOUNCE_HZ for q in p]),
            "peer_pair": float(np.mean([pair_ok(q["tilt"]) for q in p])),
            "peer_same_pole": float(np.mean([q["tilt"][0] == q["tilt"][1] for q in p])),
            "peer_zeta": float(np.nanmean([q["zeta"] / ZETA - 1 for q in p])),
            "pyfrf_ms": 1e3 * float(np.median([q["time_pyfrf"] for q in p])),
            "ema_ms": 1e3 * float(np.median([q["time_ema"] for q in p])),
            "peer_failures": sum("error" in q for q in p),
        })
    return out


def double_hit_table(seeds: int, peers: bool) -> list[dict]:
    """Detection of double hits and overloads: ours (check_impact) against pyFRF's is_data_ok."""
    rig = load_rig()
    modes = paper_case_modes(rig=rig)
    scenarios = [("clean, SNR 30 dB", {}, None), ("+1 ms / 50 %", {0: (1e-3, 0.5)}, None),
                 ("+5 ms / 30 %", {0: (5e-3, 0.3)}, None), ("+20 ms / 10 %", {0: (20e-3, 0.1)}, None),
                 ("A2Z clipped at 60 %", {}, "A2Z")]
    out = []
    for label, hits, clip in scenarios:
        ours_flags, peer_flags = [], []
        for seed in range(seeds):
            s = synth_impacts(modes, rig.channels, snr_db=30.0, seed=2000 + seed, n_impacts=1, double_hits=hits)
            if clip:
                c = rig.channels.index(clip)
                level = 0.6 * float(np.abs(s.accel_m_per_s2[0, c]).max())
                s.accel_m_per_s2[0, c] = np.clip(s.accel_m_per_s2[0, c], -level, level)
            check = check_impact(s.force_n[0], s.accel_m_per_s2[0], s.fs_hz, channels=rig.channels)
            ours_flags.append(not check.accepted)
            if peers:
                import pyFRF

                frf = pyFRF.FRF(int(round(s.fs_hz)), exc=s.force_n, resp=s.accel_m_per_s2)
                peer_flags.append(not frf.is_data_ok(s.force_n[0][None, None], s.accel_m_per_s2[0][None]))
        out.append({"scenario": label, "ours": float(np.mean(ours_flags)),
                    "peer": float(np.mean(peer_flags)) if peers else math.nan})
    return out


def fmt(v: float, spec: str) -> str:
    return "—" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20, help="impact sets per case (default 20)")
    ap.add_argument("--quick", action="store_true", help="only the SNR 40 dB, 12-channel case")
    ap.add_argument("--no-peers", action="store_true", help="skip pyFRF and sdypy-EMA")
    args = ap.parse_args(argv)
    peers = not args.no_peers
    cases = [(40.0, 12)] if args.quick else [(s, 12) for s in (20.0, 30.0, 40.0, 50.0, 60.0)] + [
        (40.0, c) for c in (1, 3, 6, 24)]
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else math.nan
    print(f"# modal processing bench: {args.seeds} impact sets per case, 3 impacts × 65 536 samples at "
          f"20 480 Hz; truth bounce {BOUNCE_HZ} Hz, tilt {TILT_HZ[0]}/{TILT_HZ[1]} Hz, ζ {ZETA}; "
          f"{os.cpu_count()} CPUs, load average {load:.1f} at start\n")
    print("| SNR dB | ch | CRLB bounce Hz | ours err Hz (×CRLB) | peers err Hz | ours/peers err | "
          "pair ±0.3 Hz ours / peers (same pole) | ζ bias ours / peers | ours ms | pyFRF ms | EMA ms | "
          "rfft ms | ours/peers time | ours/rfft (median; best) |")
    print("|---" * 14 + "|")
    for snr, ch in cases:
        r = run_case(snr, ch, args.seeds, peers)
        ratio = r["ours_err"] / r["peer_err"] if peers else math.nan
        peer_ms = r["pyfrf_ms"] + r["ema_ms"] if peers else math.nan
        print(f"| {snr:.0f} | {ch} | {r['crlb']:.2e} | {r['ours_err']:.2e} ({r['ours_err'] / r['crlb']:.2f}) | "
              f"{fmt(r.get('peer_err', math.nan), '.2e')} | {fmt(ratio, '.3f')} | "
              f"{100 * r['ours_pair']:.0f} % / {fmt(100 * r.get('peer_pair', math.nan), '.0f')} % "
              f"({fmt(100 * r.get('peer_same_pole', math.nan), '.0f')} %) | "
              f"{100 * r['ours_zeta']:+.3f} ± {100 * r['ours_zeta_se']:.3f} % / "
              f"{fmt(100 * r.get('peer_zeta', math.nan), '+.2f')} % | {r['ours_ms']:.1f} | "
              f"{fmt(r.get('pyfrf_ms', math.nan), '.0f')} | {fmt(r.get('ema_ms', math.nan), '.0f')} | "
              f"{r['floor_ms']:.1f} | {fmt(r['ours_ms'] / peer_ms, '.3f')} | {r['ours_ms'] / r['floor_ms']:.2f}; "
              f"{r['ours_best_ms'] / r['floor_best_ms']:.2f} |",
              flush=True)
    print("\n| impact (SNR 30 dB) | rejected by ours | rejected by pyFRF is_data_ok |")
    print("|---|---|---|")
    for row in double_hit_table(args.seeds, peers):
        print(f"| {row['scenario']} | {100 * row['ours']:.0f} % | {fmt(100 * row['peer'], '.0f')} % |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
