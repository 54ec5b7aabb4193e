"""``labctl programme``: many campaigns on the simulated rig in parallel (one per specimen, or the paper's 18)."""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

from labctl.cli.common import add_json, emit
from labctl.errors import InputError

EXIT_SOME_FAILED = 1


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("programme", help="run many campaigns on the simulated rig in parallel, one file each",
                       description="Run a test programme on the simulated rig: one campaign per specimen of each "
                                   "PROTOCOL (and with --paper the paper's 9 roller types on 2 rails), spread "
                                   "over worker processes or a Dask cluster. Each campaign writes OUT/NAME.h5; "
                                   "results equal a run one after another (--workers 0).")
    p.add_argument("protocols", nargs="*", metavar="PROTOCOL",
                   help="protocol TOML files (or shipped names); each specimen becomes its own campaign")
    p.add_argument("--paper", action="store_true",
                   help="add the paper's programme: roller types 1-9 on Ra 0.2 and 0.03 µm rails (18 campaigns)")
    p.add_argument("--out", required=True, metavar="DIR", help="directory for the campaign files (never overwritten)")
    p.add_argument("--seed", type=int, default=1,
                   help="seed of the first campaign; campaign i (in the order listed) runs with seed + i (default 1)")
    p.add_argument("--world", help="world scenario for the simulated rig (default: Tripp + surface roughness)")
    p.add_argument("--rig", help="rig TOML file for the protocols' campaigns (default: the paper's rig)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None, metavar="N",
                       help="local Dask cluster of N worker processes (default: one per CPU; 0: in this process)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="an existing Dask scheduler, e.g. tcp://host:8786 (its workers must reach --out)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_json(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace
    from pathlib import Path

    from labctl.programme import paper_programme, run_programme, specimen_jobs
    from labctl.storage.outputs import output_folder

    if args.workers is not None and args.workers < 0:
        raise InputError(f"--workers {args.workers}: expected 0 (this process) or more worker processes")
    if not args.protocols and not args.paper:
        raise InputError("nothing to run: name PROTOCOL files and/or --paper")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: is a file; --out names a directory for the campaign files")
    jobs = []
    for name in args.protocols:
        jobs += specimen_jobs(name, out, world=args.world, rig=args.rig)
    if args.paper:
        jobs += paper_programme(out, world=args.world)
    jobs = [replace(job, seed=args.seed + i) for i, job in enumerate(jobs)]
    names = [job.name for job in jobs]
    clash = sorted({n for n in names if names.count(n) > 1})
    if clash:
        raise InputError(f"two campaigns named {clash[0]!r} would write the same file: give protocols distinct names")
    output_folder("--out", out)
    t0 = time.perf_counter()
    done = run_programme(jobs, workers=args.workers, scheduler=args.scheduler,
                         progress=None if args.quiet or args.json else sys.stderr)
    result = {"out": str(out), "campaigns": [d.summary() | {"seed": j.seed} for d, j in zip(done, jobs, strict=True)],
              "complete": sum(d.ok for d in done), "failed": sum(not d.ok for d in done),
              "workers": args.workers, "scheduler": args.scheduler, "wall_s": time.perf_counter() - t0,
              "cpu_s": sum(d.cpu_seconds for d in done)}

    def text(r: dict[str, Any]) -> str:
        lines = [f"{c['name']:<28} {c['status']:<9} {c['repetitions']} repetitions, {c['identified_steps']:3d} "
                 f"steps identified  {c['seconds']:7.1f} s  seed {c['seed']}  {c['path']}"
                 + (f"\n  {c['message']}" if c["message"] and c["status"] != "complete" else "")
                 for c in r["campaigns"]]
        lines.append(f"{r['complete']} of {len(r['campaigns'])} campaigns complete in {r['wall_s']:.1f} s wall "
                     f"({r['cpu_s']:.1f} s CPU in the campaigns)")
        return "\n".join(lines)

    emit(result, args.json, text)
    return 0 if all(d.ok for d in done) else EXIT_SOME_FAILED
