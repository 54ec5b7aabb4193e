"""Benchmark: labctl's modal processing against pyFRF + sdypy-EMA, the bare rfft and the Cramér–Rao bound.

Run by hand, never in CI (the peers are bench-only installs, not labctl dependencies)::

    pip install -e '.[bench]'      # pyFRF and sdypy-EMA
    python bench/processing.py [--seeds 100] [--quick] [--no-peers] [--peers-all]

Every condition synthesises impact sets with known truth (tests/synth_impacts.py: bounce 745 Hz, tilt pair
580/582 Hz, ζ 0.018, 3 impacts × 65 536 samples at 20 480 Hz), fresh noise per set (responses at an SNR over the
modes' decay, force as peak to noise, 40–60 dB), and runs on the same arrays: ours (``identify``, the whole step);
pyFRF H1 + sdypy-EMA LSCF as their documentation shows; a bare ``numpy.fft.rfft`` (the floor); the Cramér–Rao
bound of the bounce frequency. It reports the bounce error against the bound (95 % intervals), how often the
stated σ covers the truth, per-roller errors, second-hit bias and double-hit / overload detection.
``--blind N``: the tables on files from the generator written by another hand (bench/processing_blind.py).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import importlib.util
import io
import math
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from intervals import boot, ci, fmt, rms, share, wilson  # noqa: E402  (bench/ is the script's folder)

from labctl.physics import RigConfig, load_rig  # noqa: E402
from labctl.physics.rig_config import Sensor  # noqa: E402
from labctl.processing import ProcessingError, check_impact, identify  # noqa: E402
from tests.synth_impacts import SynthMode, paper_case_modes, rig_set, synth_impacts  # noqa: E402

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
    try:
        r = identify(s.force_n, s.accel_m_per_s2, s.fs_hz, s.channels, rig, accel_ranges=ACCEL_RANGE,
                     force_range_n=FORCE_RANGE)
    except ProcessingError:  # "no result" is an allowed answer: counted, not scored
        return {"time": time.perf_counter() - t0, "bounce": math.nan, "std": math.nan, "tilt": (math.nan, math.nan),
                "resolved": False, "zeta": math.nan, "accepted": 0, "result": None, "failed": True}
    dt = time.perf_counter() - t0
    return {"time": dt, "bounce": r.bounce_hz, "std": r.bounce_hz_std, "tilt": r.tilt_hz,
            "resolved": r.tilt_pair_resolved, "zeta": r.bounce_damping_ratio, "accepted": len(r.accepted), "result": r}


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


DECAY_S = math.log(100.0) / (ZETA * 2 * math.pi * min(TILT_HZ))  # the slowest contact mode down to 1 %


def seeds_for(case: int, seeds: int) -> range:
    """Fresh noise per condition and per seed: no draw is shared between conditions."""
    return range(100_000 * (case + 1), 100_000 * (case + 1) + seeds)


def run_case(case: int, snr_db: float, n_channels: int, force_snr_db: float, seeds: int, peers: bool) -> dict:
    rig, channels = bench_rig(n_channels)
    modes = paper_case_modes(BOUNCE_HZ, TILT_HZ, ZETA, rig=rig, channels=channels)
    rows = []
    warm = True
    unit_bound = None
    for seed in seeds_for(case, seeds):
        s = synth_impacts(modes, channels, snr_db=snr_db, seed=seed, snr_decay_s=DECAY_S,
                          force_peak_snr_db=force_snr_db)
        if warm:
            run_ours(s, rig)  # warm caches once
            warm = False
        if unit_bound is None:  # the bound scales with the noise σ; the force's spectrum barely moves by seed
            unit_bound = crlb_hz(modes, s.force_n, s.fs_hz, 1.0)["bounce"]
        bound = unit_bound * s.truth["noise_m_per_s2"]
        ours = run_ours(s, rig)
        ours.pop("result")
        row = {"ours": ours, "floor": run_floor(s), "crlb": bound}
        if peers:
            row["peers"] = run_peers(s)
        rows.append(row)
    failed = sum(bool(r["ours"].get("failed")) for r in rows)
    rows_all = rows
    rows = [r for r in rows if not r["ours"].get("failed")]
    err = np.array([r["ours"]["bounce"] - BOUNCE_HZ for r in rows])
    std = np.array([r["ours"]["std"] for r in rows])
    crlb = np.array([r["crlb"] for r in rows])
    t_ours = np.array([r["ours"]["time"] for r in rows])
    t_floor = np.array([r["floor"] for r in rows])
    out = {
        "snr": snr_db, "channels": n_channels, "force_snr": force_snr_db, "crlb": rms(crlb), "failed": failed,
        "ours_err": rms(err), "ours_crlb": rms(err) / rms(crlb),
        "ours_crlb_ci": boot(lambda e, c: rms(e) / rms(c), err, crlb),
        "cover": wilson(int(np.sum(np.abs(err) <= 2 * std)), len(err)),
        "std_ratio": rms(err / std), "std_ratio_ci": boot(lambda z: rms(z), err / std),
        "ours_pair": wilson(int(sum(pair_ok(r["ours"]["tilt"]) for r in rows)), len(rows)),
        "false_pair": sum(r["ours"]["resolved"] and not pair_ok(r["ours"]["tilt"]) for r in rows),
        "ours_ms": 1e3 * float(np.median(t_ours)), "floor_ms": 1e3 * float(np.median(t_floor)),
        "ours_floor": float(np.median(t_ours / t_floor)),
        "ours_floor_ci": boot(lambda a, b: float(np.median(a / b)), t_ours, t_floor),
    }
    if peers:
        p = [r["peers"] for r in rows_all if not r["ours"].get("failed")]
        perr = np.array([q["bounce"] - BOUNCE_HZ for q in p])
        t_peer = np.array([q["time_pyfrf"] + q["time_ema"] for q in p])
        out.update({
            "peer_err": rms(perr), "ours_peer_err": rms(err) / rms(perr),
            "ours_peer_err_ci": boot(lambda a, b: rms(a) / rms(b), err, perr),
            "peer_pair": wilson(int(sum(pair_ok(q["tilt"]) for q in p)), len(p)),
            "peer_ms": 1e3 * float(np.median(t_peer)),
            "ours_peer_time": float(np.median(t_ours / t_peer)),
            "ours_peer_time_ci": boot(lambda a, b: float(np.median(a / b)), t_ours, t_peer),
            "peer_failures": sum("error" in q for q in p),
        })
    return out


def roller_case(case: int, factors: tuple[float, float, float], seeds: int) -> dict:
    """Unequal rollers (rig model, frequency-domain synthesis): each k_i and their mean against the truth."""
    rig = load_rig()
    k_true = 4.65e7 * np.asarray(factors)
    errs, mean_errs, z, named, wrong = [], [], [], 0, 0
    odd = {i + 1 for i in range(3) if abs(factors[i] - np.mean(factors)) > 0.01}
    for seed in seeds_for(case, seeds):
        s = rig_set(list(k_true), rig=rig, seed=seed, snr_db=40.0, snr_decay_s=DECAY_S, force_peak_snr_db=50.0)
        r = identify(s.force_n, s.accel_m_per_s2, s.fs_hz, s.channels, rig)
        k = np.asarray(r.roller_stiffnesses_n_per_m)
        errs.append(k / k_true - 1)
        mean_errs.append(r.roller_stiffness_n_per_m / k_true.mean() - 1)
        z.append((k - k_true) / np.asarray(r.roller_stiffnesses_fit_std_n_per_m))
        named += bool(odd) and odd <= set(r.rollers_differing)
        wrong += bool(set(r.rollers_differing) - odd) if odd else bool(r.rollers_differing)
    errs, z = np.array(errs), np.array(z)
    return {"factors": factors, "max_err": float(np.max(np.abs(errs))), "rms_err": rms(errs),
            "rms_err_ci": boot(lambda e: rms(e), errs.ravel()), "mean_err": float(np.mean(mean_errs)),
            "mean_err_ci": boot(lambda e: float(np.mean(e)), np.array(mean_errs)),
            "cover": wilson(int(np.sum(np.abs(z) <= 2)), z.size),
            "named": wilson(named, seeds) if odd else None, "wrong": wilson(wrong, seeds)}


def second_hit_case(case: int, delay_s: float, ratio: float, seeds: int) -> dict:
    """A small second blow on every impact: bounce bias in units of the stated σ, or the impact rejected."""
    rig = load_rig()
    modes = paper_case_modes(rig=rig)
    z, rejected, inside = [], 0, 0
    for seed in seeds_for(case, seeds):
        s = synth_impacts(modes, rig.channels, snr_db=40.0, seed=seed, snr_decay_s=DECAY_S, force_peak_snr_db=50.0,
                          double_hits={i: (delay_s, ratio) for i in range(3)})
        try:
            r = identify(s.force_n, s.accel_m_per_s2, s.fs_hz, s.channels, rig)
        except Exception:  # every impact rejected: the step's answer is "no result", which is allowed
            rejected += 1
            continue
        if not r.accepted:
            rejected += 1
            continue
        e = (r.bounce_hz - BOUNCE_HZ) / r.bounce_hz_std
        z.append(e)
        inside += abs(e) <= 2
    z = np.array(z)
    return {"delay": delay_s, "ratio": ratio, "bias": float(np.mean(z)) if len(z) else math.nan,
            "bias_ci": boot(lambda v: float(np.mean(v)), z) if len(z) > 1 else (math.nan, math.nan),
            "inside": wilson(inside, max(len(z), 1)), "rejected": wilson(rejected, seeds)}


def independent_coverage(files: int) -> dict:
    """Coverage of the stated bounce σ on the independent generator (tests/impact_generator.py: own rig
    matrices, time-domain synthesis, Hertz-like blow): 40 dB over the decay, force 40-60 dB peak to noise."""
    from tests.impact_generator import generate

    rig = load_rig()
    rng = np.random.default_rng(2024)
    z = []
    for seed in range(files):
        g = generate(rig, 4.65e7, seed=500_000 + seed, snr_db=40.0, force_snr_db=float(rng.uniform(40.0, 60.0)))
        r = identify(g.force_n, g.accel_m_per_s2, g.fs_hz, g.channels, rig)
        z.append((r.bounce_hz - g.truth["bounce_hz"]) / r.bounce_hz_std)
    z = np.array(z)
    return {"files": files, "cover": wilson(int(np.sum(np.abs(z) <= 2)), files), "rms_z": rms(z),
            "rms_z_ci": boot(lambda v: rms(v), z), "mean_z": float(np.mean(z))}


def double_hit_table(seeds: int, peers: bool) -> list[dict]:
    """Detection of double hits and overloads: ours (check_impact) against pyFRF's is_data_ok."""
    rig = load_rig()
    modes = paper_case_modes(rig=rig)
    scenarios = [("clean, SNR 30 dB", {}, None), ("+1 ms / 50 %", {0: (1e-3, 0.5)}, None),
                 ("+5 ms / 30 %", {0: (5e-3, 0.3)}, None), ("+20 ms / 10 %", {0: (20e-3, 0.1)}, None),
                 ("A2Z clipped at 60 %", {}, "A2Z")]
    out = []
    for case, (label, hits, clip) in enumerate(scenarios):
        ours_flags, peer_flags = [], []
        for seed in seeds_for(50 + case, seeds):
            s = synth_impacts(modes, rig.channels, snr_db=30.0, seed=seed, n_impacts=1, double_hits=hits,
                              snr_decay_s=DECAY_S, force_peak_snr_db=50.0)
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


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=100, help="impact sets per condition (default 100)")
    ap.add_argument("--quick", action="store_true", help="only the 40 dB, 12-channel case and the special tables")
    ap.add_argument("--no-peers", action="store_true", help="skip pyFRF and sdypy-EMA")
    ap.add_argument("--peers-all", action="store_true", help="run the peers in every case (default: 40 dB / 12 ch)")
    ap.add_argument("--from-case", type=int, default=0, metavar="K",
                    help="start the main table at its K-th condition (0-based; to finish an interrupted run)")
    ap.add_argument("--independent", type=int, metavar="N",
                    help="only the coverage check on N files of the independent generator")
    ap.add_argument("--blind", type=int, metavar="N",
                    help="only the blind generator's tables (bench/processing_blind.py): N files per preset")
    args = ap.parse_args(argv)
    if args.blind:
        from processing_blind import main as blind_main
        return blind_main([str(args.blind)])
    if args.independent:
        r = independent_coverage(args.independent)
        print(f"independent generator, {r['files']} files, 40 dB, force 40-60 dB: |error| ≤ 2σ in {share(r['cover'])}; "
              f"rms(error/σ) {r['rms_z']:.2f} {ci(r['rms_z_ci'], '.2f')}; mean(error/σ) {r['mean_z']:+.2f}")
        return 0
    peers = not args.no_peers
    if peers:
        missing = [name for name in ("pyFRF", "sdypy.EMA") if importlib.util.find_spec(name.split(".")[0]) is None]
        if missing:
            print(f"bench/processing.py: peer(s) not installed: {', '.join(missing)}; "
                  "pip install -e '.[bench]' (or run with --no-peers)", file=sys.stderr)
            return 2
    cases = [(40.0, 12, 50.0)] if args.quick else (
        [(40.0, 12, 50.0)] + [(s, 12, 50.0) for s in (20.0, 30.0, 50.0, 60.0)]
        + [(40.0, c, 50.0) for c in (1, 3, 6, 24)] + [(40.0, 12, f) for f in (40.0, 60.0, 200.0)])
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else math.nan
    print(f"# modal processing bench: {args.seeds} impact sets per condition (fresh noise for every set and "
          f"condition), 3 impacts × 65 536 samples at 20 480 Hz; truth bounce {BOUNCE_HZ} Hz, tilt "
          f"{TILT_HZ[0]}/{TILT_HZ[1]} Hz, ζ {ZETA}; response SNR over the first {1e3 * DECAY_S:.0f} ms after "
          f"the blow (the contact modes' decay to 1 %), force noise as peak to noise; 95 % intervals in brackets "
          f"(bootstrap over seeds; Wilson for shares); {os.cpu_count()} CPUs, load average {load:.1f} at start\n")
    print("| SNR dB | ch | force dB | CRLB Hz (force known) | ours err Hz | ×CRLB | |err| ≤ 2σ | rms(err/σ) | "
          "pair ±0.3 Hz | false pair | peers err Hz | ours/peers err | ours ms | rfft ms | ours/rfft | peers ms | "
          "ours/peers time |")
    print("|---" * 17 + "|")
    for case, (snr, ch, fsnr) in enumerate(cases):
        if case < args.from_case:
            continue
        with_peers = peers and (args.peers_all or (snr, ch, fsnr) == (40.0, 12, 50.0))
        r = run_case(case, snr, ch, fsnr, args.seeds, with_peers)
        pe = (f"{r['peer_err']:.2e} | {r['ours_peer_err']:.3f} {ci(r['ours_peer_err_ci'], '.3f')}"
              if with_peers else "— | —")
        pt = (f"{r['peer_ms']:.0f} | {r['ours_peer_time']:.3f} {ci(r['ours_peer_time_ci'], '.3f')}"
              if with_peers else "— | —")
        fs = "exact" if fsnr >= 200 else f"{fsnr:.0f}"
        print(f"| {snr:.0f} | {ch} | {fs} | {r['crlb']:.2e} | {r['ours_err']:.2e} | {r['ours_crlb']:.2f} "
              f"{ci(r['ours_crlb_ci'], '.2f')} | {share(r['cover'])} | {r['std_ratio']:.2f} "
              f"{ci(r['std_ratio_ci'], '.2f')} | {share(r['ours_pair'])} | {r['false_pair']} | {pe} | "
              f"{r['ours_ms']:.1f} | {r['floor_ms']:.1f} | {r['ours_floor']:.2f} {ci(r['ours_floor_ci'], '.2f')} | "
              f"{pt} |" + (f" ({r['failed']} sets: no result)" if r["failed"] else ""), flush=True)
    print("\n| rollers (× 4.65e7 N/m), 40 dB, force 50 dB | max |k_i error| | rms k_i error | mean k error | "
          "k_i within 2σ (fit) | differing roller named | a roller wrongly named |")
    print("|---" * 7 + "|")
    for case, factors in enumerate([(1.15, 1.00, 0.85), (1.00, 1.00, 1.00)]):
        r = roller_case(20 + case, factors, args.seeds)
        print(f"| {'/'.join(f'{f:.2f}' for f in factors)} | {100 * r['max_err']:.2f} % | {100 * r['rms_err']:.3f} % "
              f"{ci(tuple(100 * v for v in r['rms_err_ci']), '.3f')} | {100 * r['mean_err']:+.4f} % "
              f"{ci(tuple(100 * v for v in r['mean_err_ci']), '+.4f')} | {share(r['cover'])} | {share(r['named'])} | "
              f"{share(r['wrong'])} |", flush=True)
    print("\n| second hit on every impact (40 dB, force 50 dB) | bounce bias / stated σ | |err| ≤ 2σ | step rejected |")
    print("|---" * 4 + "|")
    for case, (delay, ratio) in enumerate([(4e-3, 0.01), (4e-3, 0.02), (4e-3, 0.03), (4e-3, 0.04),
                                           (2.5e-3, 0.03), (7e-3, 0.03)]):
        r = second_hit_case(30 + case, delay, ratio, args.seeds)
        print(f"| {100 * ratio:.0f} % at +{1e3 * delay:.1f} ms | {r['bias']:+.2f} {ci(r['bias_ci'], '+.2f')} | "
              f"{share(r['inside'])} | {share(r['rejected'])} |", flush=True)
    print("\n| impact (SNR 30 dB) | rejected by ours | rejected by pyFRF is_data_ok |")
    print("|---|---|---|")
    for row in double_hit_table(min(args.seeds, 20), peers):
        print(f"| {row['scenario']} | {100 * row['ours']:.0f} % | {fmt(100 * row['peer'], '.0f')} % |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
