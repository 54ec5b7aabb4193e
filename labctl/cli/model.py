"""``labctl model``: evaluate a contact model over loads."""

from __future__ import annotations

import argparse
from typing import Any

from labctl.cli.common import add_json, emit
from labctl.errors import InputError

MODELS = ("tripp", "palmgren", "fit-ra0.2", "fit-ra0.03", "hertz")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("model", help="evaluate a contact model (stiffness and deflection vs load)",
                       description="Evaluate a contact model. Rollers: tripp, palmgren, fit-ra0.2, fit-ra0.03 "
                                   "with --roller-type; balls: hertz with --ball-diameter-mm.")
    p.add_argument("model", choices=MODELS, metavar="MODEL", help=f"one of {', '.join(MODELS)}")
    p.add_argument("--roller-type", type=int, help="roller type from Table 1 (1-9)")
    p.add_argument("--ball-diameter-mm", type=float, help="ball diameter in mm (hertz)")
    p.add_argument("--load-n", type=float, nargs="+", required=True, metavar="F", help="load(s) per roller, N")
    p.add_argument("--depth-mm", type=float, default=3.0, help="Tripp's evaluation depth t in mm (default 3)")
    p.add_argument("--rail-material", default="1.3505", help="rail material (catalogue name, default 1.3505)")
    p.add_argument("--ball-material", default="1.3505", help="ball material for hertz (default 1.3505)")
    add_json(p)
    p.set_defaults(func=run)


def _model(args: argparse.Namespace) -> Any:
    """The chosen model, after checking the loads lie where it applies (labctl.physics.validity)."""
    from labctl.physics import FITS, EmpiricalFit, HertzBallContact, PalmgrenContact, TrippContact, material, roller
    from labctl.physics.validity import ball_load_limit_n, check_loads, roller_load_limit_n

    rail = material(args.rail_material)
    if args.model == "hertz":
        if args.ball_diameter_mm is None:
            raise InputError("hertz needs --ball-diameter-mm D (the ball's diameter in mm)")
        if not args.ball_diameter_mm > 0:
            raise InputError(f"--ball-diameter-mm {args.ball_diameter_mm}: expected a positive diameter in mm")
        ball = material(args.ball_material)
        check_loads("hertz", args.load_n, ball_load_limit_n(args.ball_diameter_mm * 1e-3, ball, rail))
        return HertzBallContact(args.ball_diameter_mm * 1e-3, ball, rail)
    if args.roller_type is None:
        raise InputError(f"{args.model} needs --roller-type N (a roller type of Table 1)")
    r = roller(args.roller_type)
    check_loads(args.model, args.load_n, roller_load_limit_n(r, rail))
    if args.model == "tripp":
        if not args.depth_mm > 0:
            raise InputError(f"--depth-mm {args.depth_mm}: expected a positive evaluation depth in mm")
        return TrippContact(r, rail, args.depth_mm * 1e-3)
    if args.model == "palmgren":
        return PalmgrenContact(r.contact_length_m)
    return EmpiricalFit(FITS[args.model], r.contact_length_m)


def run(args: argparse.Namespace) -> int:
    model = _model(args)
    k = model.stiffness_n_per_m(args.load_n)
    d = model.deflection_m(args.load_n)
    result = {
        "model": args.model,
        "load_n": list(args.load_n),
        "stiffness_n_per_m": k.tolist(),
        "deflection_m": None if d is None else d.tolist(),
    }

    def text(r: dict[str, Any]) -> str:
        rows = [f"{args.model}: load [N]   stiffness [N/m]   deflection [µm]"]
        defl = r["deflection_m"] or [None] * len(k)
        for f, kk, dd in zip(r["load_n"], r["stiffness_n_per_m"], defl, strict=True):
            rows.append(f"  {f:10.4g}   {kk:14.4e}   {'-' if dd is None else f'{dd * 1e6:.4g}'}")
        return "\n".join(rows)

    emit(result, args.json, text)
    return 0
