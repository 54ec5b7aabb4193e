"""``labctl calibrate BALLS.h5...``: disc mass and K_setup (and what else is determined) from ball runs, no FEM."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from labctl.cli.common import add_json, emit

LABELS = (("mass_kg", "disc mass", "kg", "mass_std_kg"),
          ("setup_stiffness_n_per_m", "K_setup", "N/m", "setup_stiffness_std_n_per_m"),
          ("inertia_kg_m2", "disc inertia", "kg·m²", "inertia_std_kg_m2"),
          ("support_stiffness_n_per_m", "support stiffness", "N/m", "support_stiffness_std_n_per_m"))


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("calibrate", help="calibrate the rig (disc mass, K_setup) from ball-verification campaigns")
    p.add_argument("files", nargs="+", metavar="BALLS.h5", help="campaign files with ball specimens")
    p.add_argument("--out", metavar="RIG.toml", help="write the calibrated rig description here")
    p.add_argument("--rig", metavar="NOMINAL.toml", help="nominal rig file (default: the rig stored in the campaigns)")
    p.add_argument("--no-tilt", action="store_true", help="fit the bounce frequencies only")
    add_json(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from labctl.calibration.calibrate import calibrate
    from labctl.storage.outputs import atomic_output, check_outputs

    check_outputs([("--out", args.out)], [*args.files, args.rig])
    cal = calibrate(args.files, args.rig, use_tilt=not args.no_tilt)
    result = cal.to_dict()
    result["rig_out"] = None
    if args.out:
        with atomic_output(args.out) as tmp:
            Path(tmp).write_text(cal.rig_text(), encoding="utf-8")
        result["rig_out"] = str(args.out)
    emit(result, args.json, _text)
    return 0


def _text(r: dict[str, Any]) -> str:
    sizes = ", ".join(f"{d:g}" for d in r["ball_sizes_mm"])
    lines = [f"rig calibration from {r['steps']} ball steps (balls {sizes} mm) against {r['nominal_rig']}"]
    for key, label, unit, std_key in LABELS:
        nominal = r["nominal"][key]
        if r[key] is None:
            lines.append(f"  {label:18s} not determined (held at nominal {nominal:.6g} {unit})")
        else:
            lines.append(f"  {label:18s} {r[key]:.6g} ± {r[std_key]:.2g} {unit}   (nominal {nominal:.6g}, "
                         f"{100 * (r[key] / nominal - 1):+.2f} %)")
    if r["mass_setup_correlation"] is not None:
        lines.append(f"  correlation mass–K_setup {r['mass_setup_correlation']:+.3f}")
    f = r["fit"]
    lines.append(f"fit: χ² {f['chi2']:.1f} for {f['dof']} degrees of freedom; seating scatter "
                 f"{100 * f['seating_scatter_rel']:.3g} %, load noise {f['load_noise_n']:.3g} N; largest residual "
                 f"{f['max_abs_whitened_residual']:.2f} σ")
    lines.append("cannot separate:")
    lines.extend(f"  - {c}" for c in r["cannot_separate"])
    lines.extend(f"skipped: {s}" for s in r["skipped"])
    lines.extend(f"warning: {w}" for w in r["warnings"])
    if r["rig_out"]:
        lines.append(f"calibrated rig → {r['rig_out']}")
    return "\n".join(lines)
