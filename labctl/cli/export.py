"""``labctl export FILE.h5 --uff OUT.uff``: a campaign's time records, FRFs and coherences as UFF58."""

from __future__ import annotations

import argparse
from typing import Any

from labctl.cli.common import add_json, emit, step_bar
from labctl.errors import InputError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="export a campaign's impacts, FRFs and coherences as UFF58 (docs/contracts.md)")
    p.add_argument("file", metavar="FILE.h5", help="campaign file")
    p.add_argument("--uff", required=True, metavar="OUT.uff", help="UFF file to write (replaced if it exists)")
    fmt = p.add_mutually_exclusive_group()
    fmt.add_argument("--binary", action="store_true", help="binary 58b data sets (smaller, exact, fast to read)")
    fmt.add_argument("--ascii", action="store_true", help="ASCII 58 data sets (default only up to about 100 MB: "
                     "larger exports are binary 58b unless --ascii is given)")
    p.add_argument("--series", type=int, metavar="S", help="only this specimen series")
    p.add_argument("--run", type=int, metavar="R", help="only this repetition")
    p.add_argument("--step", type=int, metavar="N", help="only this load step")
    p.add_argument("--all-impacts", action="store_true", help="also the rejected impacts (default: accepted only)")
    p.add_argument("--no-time", action="store_true", help="leave out the time records")
    p.add_argument("--no-frf", action="store_true", help="leave out the FRFs and coherences")
    p.add_argument("--manifest", metavar="M.csv", help="also write the manifest `labctl import` reads back")
    p.add_argument("--nodes", metavar="MAP", help="node numbers, e.g. 'A1=101,A2=102,A3=103,A4=104,hammer=1' "
                                                  "(default A1..A4 = 1..4, hammer = 10)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_json(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from labctl.storage.outputs import check_outputs
    from labctl.uff.mapping import parse_node_map
    from labctl.uff.writer import Selection, export_campaign

    if args.no_time and args.no_frf:
        raise InputError("--no-time and --no-frf together leave nothing to export")
    for name in ("series", "run", "step"):
        value = getattr(args, name)
        if value is not None and value < 1:
            raise InputError(f"--{name} {value}: expected a number from 1")
    check_outputs([("--uff", args.uff), ("--manifest", args.manifest)], [args.file])
    selection = Selection(series=args.series, run=args.run, step=args.step, all_impacts=args.all_impacts,
                          time=not args.no_time, frf=not args.no_frf)
    binary = True if args.binary else (False if args.ascii else None)
    with step_bar("export", args.quiet) as progress:
        done = export_campaign(args.file, args.uff, selection=selection, binary=binary,
                               nodes=parse_node_map(args.nodes), manifest=args.manifest, progress=progress)
    result = {"file": args.file, "uff": done.out, "format": "58b" if done.binary else "58", "steps": done.steps,
              "impacts": done.impacts, "time_records": done.time_records, "frfs": done.frfs,
              "coherences": done.coherences, "sets": done.sets, "manifest": done.manifest}
    emit(result, args.json, _text)
    return 0


def _text(r: dict[str, Any]) -> str:
    line = (f"{r['uff']} (UFF {r['format']}): {r['sets']} data sets from {r['steps']} step(s) — "
            f"{r['impacts']} impacts ({r['time_records']} time records), {r['frfs']} FRFs, "
            f"{r['coherences']} coherences")
    return line + (f"\nmanifest → {r['manifest']}" if r["manifest"] else "")
