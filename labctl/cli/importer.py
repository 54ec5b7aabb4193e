"""``labctl import X.uff … --manifest M.csv --out FILE.h5``: UFF58 time data from other systems as a campaign."""

from __future__ import annotations

import argparse
from typing import Any

from labctl.cli.common import add_json, emit, step_bar
from labctl.errors import InputError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("import", help="make a campaign file from UFF58 time records and a manifest of loads")
    p.add_argument("files", nargs="*", metavar="X.uff",
                   help="UFF58 files (default: the files the manifest names, relative to it)")
    p.add_argument("--manifest", required=True, metavar="M.csv",
                   help="one row per load step: file, load_cases, load_n, repetition[, step, knob_angle_deg, "
                        "roller_type, rail_ra_um]")
    p.add_argument("--out", required=True, metavar="FILE.h5", help="campaign file to create (must not exist)")
    p.add_argument("--roller-type", type=int, metavar="N", help="roller type for rows without a roller_type")
    p.add_argument("--rail-ra-um", type=float, metavar="RA", help="rail Ra in µm for rows without one (default 0.2)")
    p.add_argument("--rail-material", default="1.3505", help="rail material (default 1.3505)")
    p.add_argument("--rig", help="rig TOML file (default: the paper's rig)")
    p.add_argument("--nodes", metavar="MAP", help="node numbers, e.g. 'A1=101,A2=102,A3=103,A4=104,hammer=1' "
                                                  "(default A1..A4 = 1..4, hammer = 10)")
    p.add_argument("--sample-rate-hz", type=float, metavar="FS",
                   help="the acquisition's sample rate, when the files' 6-digit sample interval is not enough")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_json(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from labctl.data.schema import MAX_RA_UM
    from labctl.uff.importer import ImportOptions, import_uff
    from labctl.uff.mapping import parse_node_map

    if args.rail_ra_um is not None and not 0 <= args.rail_ra_um <= MAX_RA_UM:
        raise InputError(f"--rail-ra-um {args.rail_ra_um!r}: expected a roughness in [0, {MAX_RA_UM:g}] µm")
    if args.sample_rate_hz is not None and not args.sample_rate_hz > 0:
        raise InputError(f"--sample-rate-hz {args.sample_rate_hz!r}: expected a positive rate in Hz")
    opts = ImportOptions(roller_type=args.roller_type,
                         rail_ra_m=None if args.rail_ra_um is None else args.rail_ra_um * 1e-6,
                         rail_material=args.rail_material, rig=args.rig, nodes=parse_node_map(args.nodes),
                         sample_rate_hz=args.sample_rate_hz)
    with step_bar("import", args.quiet) as progress:
        done = import_uff(args.files, args.manifest, args.out, opts, progress=progress)
    result = {"out": done.out, "series": done.series, "steps": done.steps, "notes": done.notes,
              "identified": sum(1 for s in done.steps if "error" not in s)}
    emit(result, args.json, _text)
    return 0


def _text(r: dict[str, Any]) -> str:
    lines = [f"{r['out']}: {len(r['steps'])} load steps imported, {r['identified']} identified"]
    lines.append("  series run step   load [N]   impacts   bounce [Hz]   k [N/m]")
    for s in r["steps"]:
        head = f"  {s['series']:6d} {s['run']:3d} {s['step']:4d} {s['load_n']:10.1f}"
        if "error" in s:
            lines.append(f"{head}   {s['impacts']:7d}   not identified: {s['error']}")
        else:
            lines.append(f"{head}   {s['accepted']:3d}/{s['impacts']:<3d}   {s['bounce_hz']:11.3f}   "
                         f"{s['roller_stiffness_n_per_m']:.4e}")
    lines.extend(f"note: {n}" for n in r["notes"])
    return "\n".join(lines)
