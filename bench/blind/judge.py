"""Judge `labctl identify` on the blind generator's files: its frequencies, stiffnesses and σ against the truth.

Runs the public CLI (`python -m labctl identify FILE --rig MATCHED --json`) so nothing of the processing is read.

    PYTHONPATH=$PWD python bench/blind/judge.py --seeds 2 [--preset NAME ...]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from impact_generator import PRESETS, write_file


def identify(npz: Path, rig: Path) -> dict:
    """labctl identify's JSON for one file (an error exits this bench with its one-line message)."""
    run = subprocess.run([sys.executable, "-m", "labctl", "identify", str(npz), "--rig", str(rig), "--json"],
                         capture_output=True, text=True)
    if run.returncode != 0:
        sys.exit(f"{npz}: labctl identify failed ({run.returncode}): {run.stderr.strip()}")
    return json.loads(run.stdout)


def score(truth: dict, got: dict) -> dict:
    """Errors and z-scores of one file; z = (identified − truth) / identified σ."""
    k_true = np.asarray(truth["k_n_per_m"])
    k_got = np.asarray(got.get("roller_stiffnesses_n_per_m") or [got["roller_stiffness_n_per_m"]] * 3)
    k_std = np.asarray(got.get("roller_stiffnesses_std_n_per_m") or [got["roller_stiffness_std_n_per_m"]] * 3)
    tilt = sorted(got["tilt_hz"])
    return {
        "bounce_err_hz": got["bounce_hz"] - truth["bounce_hz"],
        "tilt_err_hz": max(abs(a - b) for a, b in zip(tilt, truth["tilt_hz"], strict=True)),
        "k_mean_z": (got["roller_stiffness_n_per_m"] - truth["k_mean_n_per_m"]) / got["roller_stiffness_std_n_per_m"],
        "k_mean_err_pct": 100 * (got["roller_stiffness_n_per_m"] / truth["k_mean_n_per_m"] - 1),
        "k_roller_z": ((k_got - k_true) / k_std).tolist(),
        "k_roller_err_pct": (100 * (k_got / k_true - 1)).tolist(),
        "resolved": bool(got.get("roller_stiffnesses_resolved")),
        "differing_ok": sorted(got.get("rollers_differing") or []) == truth["rollers_differing_5pct"],
        "warnings": len(got.get("warnings") or []),
    }


def main(argv: list[str] | None = None) -> int:
    """Generate, identify and print one row per file, then the coverage of the stiffness σ."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--preset", action="append", choices=list(PRESETS), help="default: every preset")
    args = ap.parse_args(argv)
    rows = []
    print(f"{'file':26s} {'bounce Δ':>9s} {'tilt Δ':>7s} {'k Δ%':>6s} {'k z':>6s} {'roller Δ% (z)':>34s} "
          f"{'res':>3s} {'diff':>4s} {'warn':>4s}")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.preset or list(PRESETS):
            for seed in range(1, args.seeds + 1):
                npz = write_file(Path(tmp), PRESETS[name], seed)
                truth = json.loads(npz.with_suffix(".json").read_text())
                s = score(truth, identify(npz, Path(tmp) / truth["rig_file"]))
                rows.append(s)
                per = " ".join(f"{e:+5.1f}({z:+4.1f})" for e, z in zip(s["k_roller_err_pct"], s["k_roller_z"],
                                                                        strict=True))
                print(f"{npz.stem:26s} {s['bounce_err_hz']:+9.3f} {s['tilt_err_hz']:7.2f} "
                      f"{s['k_mean_err_pct']:+6.2f} {s['k_mean_z']:+6.2f} {per:>34s} "
                      f"{'y' if s['resolved'] else 'n':>3s} {'ok' if s['differing_ok'] else 'NO':>4s} "
                      f"{s['warnings']:4d}")
    z_mean = np.abs([r["k_mean_z"] for r in rows])
    z_roll = np.abs([z for r in rows if r["resolved"] for z in r["k_roller_z"]])
    print(f"mean k within 1σ / 2σ: {np.mean(z_mean <= 1):.0%} / {np.mean(z_mean <= 2):.0%} of {z_mean.size}")
    if z_roll.size:
        print(f"per-roller k within 1σ / 2σ: {np.mean(z_roll <= 1):.0%} / {np.mean(z_roll <= 2):.0%} of {z_roll.size}")
    print(f"rollers_differing right in {sum(r['differing_ok'] for r in rows)} of {len(rows)} files")
    return 0


if __name__ == "__main__":
    sys.exit(main())
