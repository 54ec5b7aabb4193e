"""``labctl identify FILE.npz``: bounce, tilt pair, damping and per-roller stiffness from one load step's impacts."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

from labctl.cli.common import add_json, emit
from labctl.errors import InputError

if TYPE_CHECKING:
    from labctl.physics import TrippContact

MM = 1e-3


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("identify", help="identify the rig's modes and the roller stiffness from an impacts NPZ")
    p.add_argument("file", metavar="FILE.npz", help="impacts NPZ (fs, force, accel, channels) or UFF58 time records "
                                                    "(.uff/.unv); docs/contracts.md")
    p.add_argument("--rig", help="rig TOML file (default: the paper's rig)")
    p.add_argument("--accel-range", type=float, metavar="A",
                   help="accelerometer full scale, m/s² (default: overload seen as a clipped plateau)")
    p.add_argument("--force-range-n", type=float, metavar="F", help="force channel full scale, N")
    p.add_argument("--exp-window-end", type=float, default=0.01, metavar="E",
                   help="exponential window's value at the record end (default 0.01; 1 = no window)")
    p.add_argument("--whole-record", action="store_true",
                   help="analyse the whole record (default: up to twice the responses' ring-down, docs/processing.md)")
    p.add_argument("--min-coherence", type=float,
                   help="coherence at the bounce below which an impact is rejected (default: the checks' default)")
    roll = p.add_argument_group("roller-only stiffness (rails' Tripp compliance removed)")
    roll.add_argument("--roller-type", type=int, metavar="N", help="roller type of the catalogue (Table 1)")
    roll.add_argument("--load-n", type=float, metavar="F", help="load per roller, N")
    roll.add_argument("--depth-mm", type=float, help="rail evaluation depth t, mm (default: Tripp's default depth)")
    roll.add_argument("--rail-material", default="1.3505", help="rail material (default 1.3505)")
    add_json(p)
    p.set_defaults(func=run)


def _contact(args: argparse.Namespace) -> TrippContact | None:
    from labctl.physics import TrippContact, material, roller
    from labctl.physics.tripp import DEFAULT_DEPTH_M

    if args.depth_mm is None:
        args.depth_mm = DEFAULT_DEPTH_M / MM
    if (args.roller_type is None) != (args.load_n is None):
        raise InputError("--roller-type and --load-n go together (both are needed for the roller-only stiffness)")
    if args.roller_type is None:
        return None
    if not args.load_n > 0:
        raise InputError(f"--load-n {args.load_n!r}: expected a positive load in N")
    if not args.depth_mm > 0:
        raise InputError(f"--depth-mm {args.depth_mm!r}: expected a positive depth in mm")
    return TrippContact(roller(args.roller_type), material(args.rail_material), args.depth_mm * MM)


def run(args: argparse.Namespace) -> int:
    from labctl.physics import load_rig
    from labctl.processing import CheckConfig, IdentifyConfig, WindowConfig, identify, load_impacts_npz

    if not 0 < args.exp_window_end <= 1:
        raise InputError(f"--exp-window-end {args.exp_window_end!r}: expected a value in (0, 1]")
    for name in ("accel_range", "force_range_n"):
        value = getattr(args, name)
        if value is not None and not value > 0:
            raise InputError(f"--{name.replace('_', '-')} {value!r}: expected a positive full scale")
    if _is_hdf5(args.file):
        raise InputError(f"{args.file}: is an HDF5 campaign file, not one step's impacts: reprocess a campaign with "
                         f"'labctl process {args.file}' (identify takes an impacts .npz or UFF58 file)")
    contact = _contact(args)
    rig = load_rig(args.rig)
    if str(args.file).lower().endswith((".uff", ".unv")):  # UFF58 time records (docs/contracts.md)
        from labctl.uff import load_impacts_uff

        data = load_impacts_uff(args.file)
    else:
        data = load_impacts_npz(args.file)
    window = WindowConfig(exponential_end=None if args.exp_window_end == 1 else args.exp_window_end,
                          trim_to_decay=not args.whole_record)
    checks = CheckConfig() if args.min_coherence is None else CheckConfig(min_coherence=args.min_coherence)
    config = IdentifyConfig(checks=checks, window=window)
    result = identify(data.force_n, data.accel_m_per_s2, data.fs_hz, data.channels, rig,
                      accel_ranges=args.accel_range, force_range_n=args.force_range_n, config=config,
                      contact=contact, load_n=args.load_n)
    emit(result.to_dict(), args.json, _text)
    return 0


def _text(r: dict[str, Any]) -> str:
    t, ts = r["tilt_hz"], r["tilt_hz_std"]
    lines = [
        f"bounce  {r['bounce_hz']:.4f} ± {r['bounce_hz_std']:.4f} Hz   damping {r['bounce_damping_ratio']:.5f} "
        f"± {r['bounce_damping_ratio_std']:.1e}   coherence {r['coherence_at_bounce']:.4f}",
        f"tilt    {t[0]:.3f} ± {ts[0]:.3f} / {t[1]:.3f} ± {ts[1]:.3f} Hz"
        + ("" if r["tilt_pair_resolved"] else "   (pair not resolved)"),
        f"roller stiffness {r['roller_stiffness_n_per_m']:.5e} ± {r['roller_stiffness_std_n_per_m']:.2e} N/m",
    ]
    budget = r["roller_stiffness_budget_n_per_m"] or {}
    if budget:
        names = {"modal_fit": "modal fit", "disc_mass": "disc mass", "setup_stiffness": "K_setup",
                 "rig_model": "rig model"}
        lines.append("  1-σ budget: " + ", ".join(f"{names.get(k, k)} {v:.2e}" for k, v in budget.items()) + " N/m")
    ks, kstd = r["roller_stiffnesses_n_per_m"] or [], r["roller_stiffnesses_fit_std_n_per_m"] or []
    if ks:
        how = ("from the bounce, the tilt split and the tilt shapes" if r["roller_stiffnesses_resolved"]
               else "tilt pair unresolved: the rollers cannot be told apart")
        lines.append("  per roller: " + ", ".join(f"{i + 1}: {k:.4e} ± {s:.1e}" for i, (k, s)
                                                 in enumerate(zip(ks, kstd, strict=True))) + f" N/m ({how})")
    lin, blow = r["linearity"], r.get("blow_effect")
    if lin:
        note = ""
        if blow and blow["significant"]:
            note = (f"   (not linear: k moved ~{100 * blow['effect_rel']:.2f} % by the blows, "
                    + ("see warning)" if blow["material"] else
                       f"below {100 * blow['limit_rel']:.2f} %: within the stated σ)"))
        lines.append(f"linearity  bounce {100 * lin['slope_hz_per_n']:+.4f} ± {100 * lin['slope_std_hz_per_n']:.4f} Hz "
                     f"per 100 N of blow over {min(lin['peak_force_n']):.0f}-{max(lin['peak_force_n']):.0f} N" + note)
    if "roller_only_stiffness_n_per_m" in r:
        lines.append(f"roller alone     {r['roller_only_stiffness_n_per_m']:.5e} ± "
                     f"{r['roller_only_stiffness_std_n_per_m']:.2e} N/m (rails' Tripp compliance removed)")
    for imp in r["impacts"]:
        verdict = "accepted" if imp["accepted"] else "rejected: " + ", ".join(imp["reasons"])
        lines.append(f"impact {imp['index']}: peak {imp['peak_force_n']:.1f} N, pulse "
                     f"{1e3 * imp['pulse_width_s']:.3f} ms — {verdict}")
    lines.extend(f"warning: {w}" for w in r["warnings"])
    return "\n".join(lines)


def _is_hdf5(path: str) -> bool:
    """The file starts with HDF5's signature (a campaign file given where impacts are expected)."""
    try:
        with open(path, "rb") as fh:
            return fh.read(8) == b"\x89HDF\r\n\x1a\n"
    except OSError:
        return False
