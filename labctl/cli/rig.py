"""``labctl rig``: rig modes from roller stiffness, and roller stiffness from the bounce frequency."""

from __future__ import annotations

import argparse
from typing import Any

from labctl.cli.common import add_json, emit
from labctl.errors import InputError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("rig", help="rig dynamics: modes from stiffness, stiffness from bounce frequency")
    rs = p.add_subparsers(dest="rig_command", metavar="{modes,stiffness}")
    rs.required = True
    m = rs.add_parser("modes", help="bounce and tilt frequencies for given roller stiffness(es)")
    m.add_argument("--stiffness-n-per-m", type=float, nargs="+", required=True, metavar="K",
                   help="one value (all rollers) or three (rollers 1-3), N/m")
    m.add_argument("--rig", help="rig TOML file (default: the paper's rig)")
    add_json(m)
    m.set_defaults(func=run_modes)
    s = rs.add_parser("stiffness", help="per-roller stiffness from a bounce frequency (Eq. 4)")
    s.add_argument("--bounce-hz", type=float, required=True, help="bounce frequency, Hz")
    s.add_argument("--rig", help="rig TOML file (default: the paper's rig)")
    add_json(s)
    s.set_defaults(func=run_stiffness)


def run_modes(args: argparse.Namespace) -> int:
    from labctl.physics import load_rig, rig_modes

    ks = args.stiffness_n_per_m
    if len(ks) not in (1, 3):
        raise InputError(f"--stiffness-n-per-m takes one value or three, got {len(ks)}")
    modes = rig_modes(load_rig(args.rig), ks if len(ks) == 3 else ks[0])
    result = {
        "bounce_hz": modes.bounce_hz,
        "tilt_hz": list(modes.tilt_hz),
        "support_hz": [float(modes.frequencies_hz[i]) for i in modes.support],
        "roller_stiffness_n_per_m": [float(k) for k in (ks * 3 if len(ks) == 1 else ks)],
        "modes": [
            {"kind": kind, "frequency_hz": float(modes.frequencies_hz[i]),
             "damping_ratio": float(modes.damping_ratios[i]), "shape": modes.sensor_shapes(i)}
            for kind, i in [("bounce", modes.bounce), ("tilt", modes.tilt[0]), ("tilt", modes.tilt[1])]
        ],
    }

    def text(r: dict[str, Any]) -> str:
        t = r["tilt_hz"]
        return (f"bounce {r['bounce_hz']:.2f} Hz   tilt {t[0]:.2f} / {t[1]:.2f} Hz   "
                f"support {', '.join(f'{f:.1f}' for f in r['support_hz'])} Hz")

    emit(result, args.json, text)
    return 0


def run_stiffness(args: argparse.Namespace) -> int:
    from labctl.physics import load_rig, roller_stiffness_from_bounce

    k = roller_stiffness_from_bounce(load_rig(args.rig), args.bounce_hz)
    emit({"bounce_hz": args.bounce_hz, "roller_stiffness_n_per_m": k}, args.json,
         lambda r: f"per-roller stiffness {r['roller_stiffness_n_per_m']:.4e} N/m at {r['bounce_hz']:g} Hz")
    return 0
