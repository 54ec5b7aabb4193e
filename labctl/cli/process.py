"""``labctl process``: recompute every step of a campaign from its raw impacts; export the stiffness table."""

from __future__ import annotations

import argparse
from typing import Any

from labctl.cli.common import add_json, emit
from labctl.errors import InputError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("process", help="(re)process a campaign file; export the stiffness table as CSV")
    p.add_argument("file", metavar="FILE.h5", help="campaign file")
    p.add_argument("--csv", metavar="OUT", help="write the stiffness table (one row per identified step) to this CSV")
    p.add_argument("--rig", help="rig TOML file to process with (e.g. a calibrated rig; default: the stored rig)")
    add_json(p)
    p.set_defaults(func=run)


def _roller_points(path: str, done: Any) -> tuple[list[Any], list[int]]:
    """The stiffness-table points of the roller series (a ball series is a Hertz point contact: its diameter is
    no contact length), and the ball series left out."""
    from labctl.storage import CampaignReader

    with CampaignReader(path) as reader:
        balls = [s for s in reader.series_indices() if reader.specimen(s).kind == "ball"]
    identified = [r for r in done.rows if r.result.identified]
    return [p for r, p in zip(identified, done.points, strict=True) if r.series not in balls], balls


def run(args: argparse.Namespace) -> int:
    from labctl.report.notes import step_events
    from labctl.reprocess import process_campaign
    from labctl.stiffness_table import write_stiffness_table
    from labctl.storage.outputs import atomic_output, check_outputs
    from labctl.storage.records import result_summary
    from labctl.storage.runlog import summarize

    check_outputs([("--csv", args.csv)], [args.file, args.rig])
    done = process_campaign(args.file, rig=args.rig)
    points, balls = done.points, []
    if args.csv:
        points, balls = _roller_points(args.file, done)
        if not points:
            raise InputError(f"--csv {args.csv}: {args.file} holds no identified roller step (series "
                             f"{', '.join(map(str, balls)) or '-'} are balls: Hertz point contacts, not rows of a "
                             "stiffness table of line contacts; see labctl report or labctl calibrate)")
        with atomic_output(args.csv) as tmp:
            write_stiffness_table(tmp, points)
    steps = []
    for r in done.rows:
        item = {"series": r.series, "specimen": r.specimen, "run": r.run, "step": r.step, "load_n": r.load_n,
                "knob_angle_deg": r.knob_angle_deg, "used_impacts": list(r.result.used_attempts),
                "rejected_impacts": r.result.rejected_count, **result_summary(r.result)}
        if r.info is not None:  # what happened at the rig: drift, channels left out, overrides with reasons
            item.update(step_events(r.info, r.result).to_dict())
        steps.append(item)
    log = summarize(done.log)
    result = {"path": done.path, "status": done.status, "steps": steps, "points": len(points),
              "csv": args.csv, "ball_series_left_out": balls,
              "log": {"entries": log.entries, "by_kind": log.by_kind, "by_level": log.by_level,
                                       "warnings": log.warnings, "errors": log.errors}}

    def text(res: dict) -> str:
        lines = [f"{res['path']} ({res['status']}): {res['points']} stiffness points"
                 + (f" → {res['csv']}" if res["csv"] else "")]
        if res["ball_series_left_out"]:
            lines.append(f"  ball series {', '.join(map(str, res['ball_series_left_out']))} left out of the CSV "
                         "(point contacts, not rows of a roller stiffness table)")
        lg = res["log"]
        kinds = ", ".join(f"{n} {k}" for k, n in lg["by_kind"].items())
        lines.append(f"  run log: {lg['warnings']} warning(s), {lg['errors']} error(s)"
                     + (f" in {lg['entries']} entries ({kinds})" if lg["entries"] else " (no entries)"))
        lines.append("  run step   load [N]   bounce [Hz]   k [N/m]       1-σ [N/m]")
        for s in res["steps"]:
            if s["error"]:
                lines.append(f"  {s['run']:3d} {s['step']:4d} {s['load_n']:10.1f}   not identified: {s['error']}")
            else:
                std = s["roller_stiffness_std_n_per_m"]
                std = float("nan") if std is None else std  # JSON keeps a non-finite 1-σ as null
                lines.append(f"  {s['run']:3d} {s['step']:4d} {s['load_n']:10.1f}   {s['bounce_hz']:10.2f}"
                             f"   {s['roller_stiffness_n_per_m']:.4e}   {std:.2e}"
                             + (f"   rollers {', '.join(map(str, s['rollers_differing']))} differ"
                                if s["rollers_differing"] else ""))
            lines += [f"             note: {n}" for n in s.get("notes", [])]
        return "\n".join(lines)

    emit(result, args.json, text)
    return 0
