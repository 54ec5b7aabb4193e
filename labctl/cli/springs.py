"""``labctl springs characterise|fit``: measure the star-knob spring stacks with a load cell, then write the
knob-angle → load curve into a rig file so campaigns can run with ``load_source = "springs"`` (no load cell)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from labctl.cli.common import add_json, emit
from labctl.errors import InputError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("springs", help="characterise the spring stacks and fit the rig file's [springs] curve")
    cmds = p.add_subparsers(dest="springs_command", metavar="SUBCOMMAND")
    cmds.required = True
    c = cmds.add_parser("characterise", help="run a spring characterisation protocol (needs a load cell)")
    c.add_argument("protocol", metavar="PROTOCOL.toml", help="e.g. protocols/spring_characterisation.toml")
    c.add_argument("--out", required=True, metavar="SPRINGS.h5", help="file for the readings (never overwritten)")
    c.add_argument("--backend", choices=("sim", "hw"), default="sim")
    c.add_argument("--world", help="world scenario of the simulated rig (e.g. springs)")
    c.add_argument("--seed", type=int, help="seed of the simulated rig")
    c.add_argument("--rig", metavar="RIG.toml", help="rig file (default: the shipped paper rig)")
    c.add_argument("--devices", metavar="DEVICES.toml", help="devices file for --backend hw")
    add_json(c)
    c.set_defaults(func=run_characterise)
    f = cmds.add_parser("fit", help="fit the knob-angle → load curve and write it into a rig file")
    f.add_argument("file", metavar="SPRINGS.h5", help="a characterisation file")
    f.add_argument("--rig", metavar="RIG.toml", help="rig file to add [springs] to (default: the one stored)")
    f.add_argument("--out", metavar="RIG.toml", help="write the rig file with its [springs] table here")
    add_json(f)
    f.set_defaults(func=run_fit)


def run_characterise(args: argparse.Namespace) -> int:
    from contextlib import ExitStack

    from labctl.backends import make_rig
    from labctl.calibration.spring_run import characterise, load_spring_protocol, write_characterisation
    from labctl.physics import ContactCase, load_rig, material, roller

    proto = load_spring_protocol(args.protocol)
    out = Path(args.out)
    if out.exists():
        raise InputError(f"{out}: already exists; a characterisation never overwrites a file (choose another --out)")
    config = load_rig(args.rig)
    case = ContactCase(roller(1), material("1.3505"), 0.2e-6)  # any seated specimen: the springs do not see it
    rig = make_rig(args.backend, case=case, rig=config, world=args.world, seed=args.seed, devices=args.devices)
    with ExitStack() as stack:
        for inst in (rig.load_cell, rig.actuator):
            inst.__enter__()
            stack.callback(inst.__exit__, None, None, None)
        data = characterise(rig, proto, config.roller_count, str(out))
    write_characterisation(out, data, proto, Path(config.source).read_text(encoding="utf-8"),
                           {"backend": rig.backend, **rig.description})
    result = {"file": str(out), "readings": int(data.angle_deg.size), "max_angle_deg": float(data.angle_deg.max()),
              "max_load_n": float(data.load_n.max()), "backend": rig.backend}
    emit(result, args.json, lambda r: f"{r['readings']} readings up to {r['max_angle_deg']:g}° "
                                      f"({r['max_load_n']:.1f} N per roller) → {r['file']}")
    return 0


def run_fit(args: argparse.Namespace) -> int:
    from labctl.calibration.spring_run import read_characterisation
    from labctl.calibration.springs import fit_spring_curve, rig_text_with_springs

    data, stored_rig = read_characterisation(args.file)
    curve = fit_spring_curve(data)
    rig_text, rig_source = stored_rig, f"{args.file} (stored rig)"
    if args.rig:
        rig_path = Path(args.rig)
        if not rig_path.is_file():
            raise InputError(f"{rig_path}: rig file not found")
        rig_text, rig_source = rig_path.read_text(encoding="utf-8"), str(rig_path)
    result: dict[str, Any] = {
        "file": args.file, "preload_n": curve.preload_n, "rate_n_per_deg": curve.rate_n_per_deg,
        "curvature_n_per_deg2": curve.curvature_n_per_deg2, "hysteresis_n": curve.hysteresis_n,
        "slack_deg": curve.slack_deg, "residual_std_n": curve.residual_std_n,
        "max_angle_deg": curve.max_angle_deg, "load_at_max_n": curve.load_n(curve.max_angle_deg),
        "load_std_at_max_n": curve.load_std_n(curve.max_angle_deg), "rig_out": None}
    if args.out:
        out = Path(args.out)
        if out.resolve() in {Path(args.file).resolve(), *([Path(args.rig).resolve()] if args.rig else [])}:
            raise InputError(f"{out}: is an input; write the rig file with its [springs] table elsewhere")
        out.write_text(rig_text_with_springs(rig_text, rig_source, curve, Path(args.file).name), encoding="utf-8")
        result["rig_out"] = str(out)
    emit(result, args.json, _text)
    return 0


def _text(r: dict[str, Any]) -> str:
    lines = [f"spring curve from {r['file']} (knob angle → load per roller, loading branch):",
             f"  preload   {r['preload_n']:.2f} N",
             f"  rate      {r['rate_n_per_deg']:.5g} N/° ({180 * r['rate_n_per_deg']:.1f} N per half turn)",
             f"  curvature {r['curvature_n_per_deg2']:.3g} N/°²",
             f"  hysteresis {r['hysteresis_n']:.2f} N (unloading above loading)",
             f"  slack     {r['slack_deg']:.1f}° before the springs bite",
             f"  scatter   {r['residual_std_n']:.2f} N (1-σ of one setting about the curve)",
             f"  at {r['max_angle_deg']:g}°: {r['load_at_max_n']:.1f} ± {r['load_std_at_max_n']:.2f} N"]
    if r["rig_out"]:
        lines.append(f"rig file with [springs] → {r['rig_out']}")
    return "\n".join(lines)
