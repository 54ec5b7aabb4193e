"""``labctl archive``: catalogue a lab's campaign files, query the catalogue, reprocess many files in parallel."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from labctl.cli.common import add_json, emit, say
from labctl.errors import InputError

DEFAULT_DB = "labctl-archive.db"
EXIT_SOME_FAILED = 1
_TEXT_COLUMNS = {
    "steps": ("file_name", "series", "run", "step", "roller_type", "rail_ra_um", "load_n", "stiffness_n_per_m",
              "result_source"),
    "campaigns": ("file_name", "status", "protocol_name", "created_utc", "n_steps", "n_identified", "error"),
}


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("archive", help="catalogue, query and reprocess a lab's campaign files (docs/archive.md)",
                       description="Catalogue many campaign files in an SQLite file, query it, and reprocess "
                                   "campaigns in parallel with Dask.")
    verbs = p.add_subparsers(dest="archive_command", metavar="{index,query,process}")
    verbs.required = True

    ix = verbs.add_parser("index", help="add new or changed campaign files under DIRs to the catalogue")
    ix.add_argument("paths", nargs="+", metavar="DIR", help="folders (searched recursively for *.h5) or files")
    ix.add_argument("--db", default=DEFAULT_DB, metavar="FILE", help=f"catalogue file (default {DEFAULT_DB})")
    add_json(ix)
    ix.set_defaults(func=run_index)

    q = verbs.add_parser("query", help="rows of the catalogue matching a WHERE clause; its stiffness table as CSV")
    q.add_argument("where", nargs="?", default="", metavar="WHERE",
                   help="SQL expression over the view's columns, e.g. \"roller_type = 1 and rail_ra_um = 0.2\"")
    q.add_argument("--view", choices=("steps", "campaigns"), default="steps",
                   help="one row per load step (default) or per campaign file")
    q.add_argument("--db", default=DEFAULT_DB, metavar="FILE", help=f"catalogue file (default {DEFAULT_DB})")
    q.add_argument("--csv", metavar="OUT", help="write the matching steps as a stiffness-table CSV")
    q.add_argument("--columns", metavar="A,B,...", help="columns to print (default: a short selection)")
    add_json(q)
    q.set_defaults(func=run_query)

    pr = verbs.add_parser("process", help="reprocess campaign files in parallel; results go beside each file")
    pr.add_argument("paths", nargs="+", metavar="FILE_OR_DIR", help="campaign files, or folders searched for *.h5")
    where = pr.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None, metavar="N",
                       help="local Dask cluster of N worker processes (default: one per CPU; 0: in this process)")
    where.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler, e.g. tcp://host:8786")
    pr.add_argument("--db", metavar="FILE", help="update this catalogue with the reprocessed files")
    pr.add_argument("--quiet", action="store_true", help="no progress bar")
    add_json(pr)
    pr.set_defaults(func=run_process)


def run_index(args: argparse.Namespace) -> int:
    from labctl.archive import campaign_files, index
    from labctl.storage.outputs import check_outputs

    check_outputs([("--db", args.db)], campaign_files(args.paths), allow_campaign=True)
    report = index(args.db, args.paths)
    result = {"db": args.db, **report.to_dict()}

    def text(r: dict[str, Any]) -> str:
        lines = [f"{r['db']}: {len(r['new'])} new, {len(r['updated'])} updated, {r['unchanged']} unchanged, "
                 f"{len(r['removed'])} removed, {len(r['failed'])} unreadable"]
        lines += [f"  unreadable: {f['error']}" for f in r["failed"]]
        return "\n".join(lines)

    emit(result, args.json, text)
    return EXIT_SOME_FAILED if report.failed else 0


def _fmt(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def run_query(args: argparse.Namespace) -> int:
    from labctl.archive import query, stiffness_points
    from labctl.stiffness_table import write_stiffness_table
    from labctl.storage.outputs import atomic_output, check_outputs

    check_outputs([("--csv", args.csv)], [args.db])
    res = query(args.db, args.where, view=args.view)
    columns = tuple(c.strip() for c in args.columns.split(",")) if args.columns else _TEXT_COLUMNS[args.view]
    unknown = [c for c in columns if c not in res.columns]
    if unknown:
        raise InputError(f"--columns: no column {', '.join(map(repr, unknown))} in view {args.view}; columns are "
                         f"{', '.join(res.columns)}")
    points_written = left_out = None
    if args.csv:
        if args.view != "steps":
            raise InputError("--csv writes a stiffness table: use it with the steps view")
        points, left_out = stiffness_points(res.rows)
        if not points:
            raise InputError(f"query {args.where!r}: no identified roller stiffness among {len(res.rows)} rows; "
                             "no stiffness table written")
        with atomic_output(args.csv) as tmp:
            write_stiffness_table(tmp, points)
        points_written = len(points)
    result = {"view": res.view, "where": res.where, "count": len(res.rows), "columns": list(res.columns),
              "rows": res.rows, "csv": args.csv, "points": points_written, "left_out": left_out}

    def text(r: dict[str, Any]) -> str:
        table = [list(columns)] + [[_fmt(row[c]) for c in columns] for row in r["rows"]]
        widths = [max(len(line[i]) for line in table) for i in range(len(columns))]
        numeric = [all(isinstance(row[c], int | float | None) for row in r["rows"]) for c in columns]
        lines = ["  ".join((cell.rjust(w) if num else cell.ljust(w)) for cell, w, num in
                           zip(line, widths, numeric, strict=True)).rstrip() for line in table]
        lines.append(f"{r['count']} rows")
        if r["csv"]:
            lines.append(f"stiffness table: {r['points']} points → {r['csv']}"
                         + (f" ({r['left_out']} rows without an identified stiffness left out)" if r["left_out"]
                            else ""))
        return "\n".join(lines)

    emit(result, args.json, text)
    return 0


def run_process(args: argparse.Namespace) -> int:
    from labctl.archive import campaign_files, index, process_files

    if args.workers is not None and args.workers < 0:
        raise InputError(f"--workers {args.workers}: expected 0 (in this process) or a positive number of workers")
    files = campaign_files(args.paths)
    if not files:
        raise InputError(f"no campaign files (*.h5) in {', '.join(args.paths)}")
    from labctl.archive.catalogue import check_catalogue
    from labctl.storage.outputs import check_outputs

    check_outputs([("--db", args.db)], files, allow_campaign=True)
    if args.db:
        check_catalogue(args.db)  # before any file is processed, not after
    workers = args.workers
    if workers is None and not args.scheduler:
        import os

        workers = os.cpu_count() or 1
    if args.scheduler and not (args.quiet or args.json):
        from labctl.archive.runner import CONNECT_TIMEOUT_S

        say(f"connecting to the Dask scheduler {args.scheduler} (gives up after {CONNECT_TIMEOUT_S:g} s)...")
    outcomes = process_files(files, workers=workers, scheduler=args.scheduler,
                             progress=None if args.quiet or args.json else sys.stderr)
    failed = [o for o in outcomes if not o.ok]
    indexed = index(args.db, files).to_dict() if args.db else None
    result = {"files": len(outcomes), "processed": len(outcomes) - len(failed), "failed": len(failed),
              "written": sum(o.written for o in outcomes), "workers": workers, "scheduler": args.scheduler,
              "outcomes": [o.to_dict() for o in outcomes], "db": args.db, "index": indexed}

    def text(r: dict[str, Any]) -> str:
        lines = [f"{r['processed']}/{r['files']} campaign files reprocessed "
                 f"({r['written']} results files written, {r['processed'] - r['written']} already up to date)"]
        lines += [f"  failed: {o['error']}" for o in r["outcomes"] if not o["ok"]]
        if r["db"]:
            lines.append(f"catalogue {r['db']} updated")
        return "\n".join(lines)

    emit(result, args.json, text)
    return EXIT_SOME_FAILED if failed else 0
