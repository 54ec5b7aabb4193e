"""The processing judged on the blind impact generator (bench/blind/impact_generator.py, written without reading
labctl's processing): per-roller coverage, rollers called different, tilt-pair "resolved" and every warning's rate.

    python bench/processing.py --blind 8          # 8 files per preset, 40 dB response SNR, matched rig
    python bench/processing_blind.py 8 [--snr-db 40] [--presets equal,asym_small,...] [--asymmetry-prior 0.06]

Each file is identified in this process against its matched rig TOML (the generator's own masses, inertia,
K_setup and support; its [uncertainty] table the paper rig's, so the inertia asymmetry and the sensors'
cross-axis coupling get labctl's documented defaults). The generator's presets: equal rollers, ±15 % rollers
(permuted), discs whose inertias differ (1–3 Hz or 7–9 Hz tilt split with equal rollers), accelerometers with
2–3 % transverse sensitivity, ≤ 2° mounting error and ±2 % gain errors, and their combinations.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[0]))
sys.path.insert(0, str(HERE / "blind"))
sys.path.insert(0, str(HERE))

from impact_generator import PRESETS, generate, paper_rig, rig_toml  # noqa: E402
from intervals import share, wilson  # noqa: E402

from labctl.physics.rig_config import rig_from_text  # noqa: E402
from labctl.processing import ProcessingError, identify  # noqa: E402

DEFAULT_PRESETS = ("equal", "unequal_15", "asym_small", "asym_large", "transverse", "unequal_transverse",
                   "unequal_asym")
CLEAN = ("equal", "asym_small", "transverse")  # no roller differs, the rig's asymmetry small: warnings are false


def warning_kind(text: str) -> str:
    """A warning's kind: its text up to the first number or colon (the numbers change from file to file)."""
    head = text.split(":")[0]
    for i, ch in enumerate(head):
        if ch.isdigit() or ch in "+-(":
            head = head[:i]
            break
    return head.strip()


def run_file(preset: str, seed: int, snr_db: float, asymmetry_prior: float | None = None) -> dict:
    case = replace(PRESETS[preset], snr_db=(snr_db, snr_db))
    arrays, truth = generate(case, seed)
    rig = rig_from_text(rig_toml(paper_rig(), case, f"blind ({preset})"), f"blind_{preset}_rig.toml")
    if asymmetry_prior is not None:  # a rig file stating another class of disc asymmetry
        rig = replace(rig, uncertainty=replace(rig.uncertainty, inertia_asymmetry_rel=asymmetry_prior))
    t0 = time.perf_counter()
    try:
        r = identify(arrays["force"], arrays["accel"], float(arrays["fs"]), [str(c) for c in arrays["channels"]], rig)
    except ProcessingError as exc:
        return {"failed": str(exc)}
    ms = 1e3 * (time.perf_counter() - t0)
    k_true = np.asarray(truth["k_n_per_m"])
    k = np.asarray(r.roller_stiffnesses_n_per_m)
    std = np.asarray(r.roller_stiffnesses_fit_std_n_per_m)
    tilt_true = truth["tilt_hz"]
    split_true = tilt_true[1] - tilt_true[0]
    split_std = float(np.hypot(*r.tilt_hz_std))
    return {"z": (k - k_true) / std, "named": set(r.rollers_differing), "truth": set(truth["rollers_differing_5pct"]),
            "resolved": r.tilt_pair_resolved, "split_true": split_true, "split_std": split_std,
            "tilt_err": max(abs(a - b) for a, b in zip(sorted(r.tilt_hz), tilt_true, strict=True)),
            "tilt_z": max(abs(a - b) / s for a, b, s in zip(sorted(r.tilt_hz), tilt_true, r.tilt_hz_std,
                                                             strict=True)) if r.tilt_pair_resolved else 0.0,
            "bounce_z": (r.bounce_hz - truth["bounce_hz"]) / r.bounce_hz_std,
            "mean_err": r.roller_stiffness_n_per_m / float(k_true.mean()) - 1.0,
            "mean_z": (r.roller_stiffness_n_per_m - float(k_true.mean()))
            / r.roller_stiffness_budget_n_per_m["modal_fit"],
            "warnings": [warning_kind(w) for w in r.warnings], "ms": ms}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", type=int, help="files per preset")
    ap.add_argument("--snr-db", type=float, default=40.0, help="response SNR over the decay (default 40)")
    ap.add_argument("--presets", default=",".join(DEFAULT_PRESETS))
    ap.add_argument("--asymmetry-prior", type=float, default=None, metavar="REL",
                    help="the matched rig's [uncertainty] inertia_asymmetry_rel (default: the paper rig's, 0.02)")
    args = ap.parse_args(argv)
    presets = [p for p in args.presets.split(",") if p]
    unknown = [p for p in presets if p not in PRESETS]
    if unknown:
        print(f"--presets: unknown {', '.join(unknown)}; expected among {', '.join(PRESETS)}", file=sys.stderr)
        return 2
    prior = "the paper rig's" if args.asymmetry_prior is None else f"{args.asymmetry_prior:g}"
    print(f"# blind generator, {args.files} files per preset (seeds 1..{args.files}), response SNR {args.snr_db:g} dB "
          f"over the decay, force 40-60 dB, matched rig (inertia asymmetry prior "
          f"{prior}); per-roller σ: roller_stiffnesses_fit_std_n_per_m; 95 % "
          "Wilson intervals\n")
    print("| preset | files | k_i within 2σ | k_i within 3σ | a roller called different (no roller differs) | "
          "the differing two named | pair resolved | resolved & a tilt > 3.29σ off | bounce within 2σ | "
          "rms(k_i err/σ) | mean k within 2σ (modal fit) | max |mean k err| | ms |")
    print("|---" * 13 + "|")
    clean_warn: Counter[str] = Counter()
    clean_files = 0
    for preset in presets:
        rows = [run_file(preset, seed, args.snr_db, args.asymmetry_prior) for seed in range(1, args.files + 1)]
        ok = [r for r in rows if "failed" not in r]
        z = np.concatenate([r["z"] for r in ok]) if ok else np.zeros(0)
        n_k = len(z)
        equal = [r for r in ok if not r["truth"]]
        unequal = [r for r in ok if r["truth"]]
        called = sum(1 for r in equal if r["named"])
        named_right = sum(1 for r in unequal if r["named"] == r["truth"])
        resolved = [r for r in ok if r["resolved"]]
        false_resolved = sum(1 for r in resolved if r["tilt_z"] > 3.29)
        bz = np.array([r["bounce_z"] for r in ok])
        mz = np.array([r["mean_z"] for r in ok])
        print(f"| {preset} | {len(ok)}/{len(rows)} | {share(wilson(int(np.sum(np.abs(z) <= 2)), n_k))} | "
              f"{share(wilson(int(np.sum(np.abs(z) <= 3)), n_k))} | "
              + (f"{called}/{len(equal)}" if equal else "—") + " | "
              + (f"{named_right}/{len(unequal)}" if unequal else "—")
              + f" | {len(resolved)}/{len(ok)} | {false_resolved}/{len(resolved)} | "
              f"{share(wilson(int(np.sum(np.abs(bz) <= 2)), len(bz)))} | {float(np.sqrt(np.mean(z**2))):.2f} | "
              f"{share(wilson(int(np.sum(np.abs(mz) <= 2)), len(mz)))} | "
              f"{100 * max(abs(r['mean_err']) for r in ok):.3f} % | "
              f"{np.median([r['ms'] for r in ok]):.0f} |",
              flush=True)
        if preset in CLEAN:
            clean_files += len(ok)
            for r in ok:
                clean_warn.update(set(r["warnings"]))
    if clean_files:
        print(f"\nwarnings on clean files ({', '.join(p for p in CLEAN if p in presets)}: equal rollers, a 1-3 Hz "
              f"disc asymmetry or transverse sensitivity; {clean_files} files):")
        if not clean_warn:
            print("  none")
        for kind, n in clean_warn.most_common():
            print(f"  {n}/{clean_files} files: {kind}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
