"""Reprocessing an archive: N simulated campaigns sequentially in one process vs on a local Dask cluster.

Run by hand: ``python bench/archive.py [--campaigns 12] [--workers 2] [--repeat 2]``. It simulates the campaigns
(roller type 1, 3 load steps × 2 repetitions × 3 impacts of 65 536 samples: ~60 MB and 18 impacts each, a
small real campaign), then times ``labctl.archive.process_files`` with ``workers=0`` (in this process) and on
a warm LocalCluster of ``--workers`` processes, alternating, and prints the speed-up, the cluster start-up
time, the per-campaign and per-impact cost and the load average (the machine may be shared).
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's labctl, also in the workers

from labctl.archive import process_files
from labctl.archive.runner import dask_client
from labctl.campaign import run_campaign
from labctl.storage.results import results_path

PROTOCOL = """[protocol]
name = "archive_bench"
description = "Roller type 1, three 360° steps, two repetitions, three impacts of 65 536 samples"
version = 1

[specimen]
kind = "roller"
roller_type = 1
rail_ra_um = 0.2
max_load_n = 200.0
knob_step_deg = 360.0

[loading]
settle_poll_s = 0.0

[acquisition]
samples = {samples}
impacts_per_step = 3

[repetitions]
count = 2
"""


def make_campaigns(folder: Path, n: int, samples: int) -> list[Path]:
    proto = folder / "bench.toml"
    proto.write_text(PROTOCOL.format(samples=samples), encoding="utf-8")
    out = []
    for i in range(n):
        path = folder / f"campaign_{i:03d}.h5"
        if not path.exists():
            assert run_campaign(proto, out=path, seed=100 + i).status == "complete"
        out.append(path)
    return out


def _clear(paths: list[Path]) -> None:
    for p in paths:
        results_path(p).unlink(missing_ok=True)


def _timed(paths: list[Path], **where: Any) -> tuple[float, float]:
    """Wall time of reprocessing every file, and the CPU time its tasks used (summed over the files)."""
    _clear(paths)
    t0 = time.perf_counter()
    outs = process_files(paths, **where)
    dt = time.perf_counter() - t0
    assert all(o.ok and o.written for o in outs), [o.error for o in outs if not o.ok]
    return dt, sum(o.cpu_seconds for o in outs)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--campaigns", type=int, default=12, help="number of campaigns (default 12)")
    ap.add_argument("--samples", type=int, default=65536, help="samples per impact (default 65536)")
    ap.add_argument("--workers", type=int, default=2, help="local Dask workers (default 2)")
    ap.add_argument("--repeat", type=int, default=2, help="alternating sequential/parallel rounds (default 2)")
    ap.add_argument("--dir", help="keep the campaigns in this folder (reused when present)")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    args = ap.parse_args()

    folder = Path(args.dir) if args.dir else Path(tempfile.mkdtemp(prefix="labctl-archive-bench-"))
    folder.mkdir(parents=True, exist_ok=True)
    try:
        t0 = time.perf_counter()
        paths = make_campaigns(folder, args.campaigns, args.samples)
        made_s = time.perf_counter() - t0
        size_mb = sum(p.stat().st_size for p in paths) / 1e6
        load_before = os.getloadavg()
        seq, par, cpu_seq, cpu_par = [], [], [], []
        t0 = time.perf_counter()
        with dask_client(args.workers) as client:
            client.run(importlib.import_module, "labctl.archive.runner")  # workers import labctl once, untimed
            startup_s = time.perf_counter() - t0
            for _ in range(args.repeat):
                for wall, cpu, (dt, c) in ((seq, cpu_seq, _timed(paths, workers=0)),
                                           (par, cpu_par, _timed(paths, scheduler=client.scheduler.address))):
                    wall.append(dt)
                    cpu.append(c)
        load_after = os.getloadavg()
        _clear(paths)
    finally:
        if not args.dir:
            shutil.rmtree(folder, ignore_errors=True)

    n = len(paths)
    impacts = n * 3 * 2 * 3
    t_seq, t_par = statistics.median(seq), statistics.median(par)
    result = {
        "campaigns": n, "samples": args.samples, "impacts": impacts, "data_mb": round(size_mb, 1),
        "cpu_count": os.cpu_count(), "workers": args.workers, "repeat": args.repeat,
        "sequential_s": [round(s, 3) for s in seq], "parallel_s": [round(s, 3) for s in par],
        "speedup_median": round(t_seq / t_par, 3),
        "speedup_per_round": [round(s / p, 3) for s, p in zip(seq, par, strict=True)],
        # CPU time the tasks got per second of wall time: how many cores the machine's load left us
        "cores_sequential": [round(c / w, 2) for c, w in zip(cpu_seq, seq, strict=True)],
        "cores_parallel": [round(c / w, 2) for c, w in zip(cpu_par, par, strict=True)],
        "speedup_with_startup": round(t_seq / (t_par + startup_s), 3),
        "cluster_startup_s": round(startup_s, 2), "per_campaign_s": round(t_seq / n, 4),
        "cpu_per_campaign_s_sequential": round(statistics.median(cpu_seq) / n, 4),
        "cpu_per_campaign_s_workers": round(statistics.median(cpu_par) / n, 4),
        "per_impact_ms": round(1e3 * t_seq / impacts, 2), "throughput_mb_per_s_per_worker": round(size_mb / t_seq, 1),
        "load_average_before": [round(x, 2) for x in load_before],
        "load_average_after": [round(x, 2) for x in load_after], "simulate_s": round(made_s, 1),
    }
    if args.json:
        print(json.dumps(result))
        return
    print(f"{n} campaigns, {impacts} impacts of {args.samples} samples, {size_mb:.0f} MB; "
          f"{os.cpu_count()} CPUs; load average {load_before[0]:.2f} before, {load_after[0]:.2f} after")
    print(f"sequential (1 process):       {', '.join(f'{s:.2f}' for s in seq)} s")
    print(f"local cluster ({args.workers} workers):    {', '.join(f'{s:.2f}' for s in par)} s "
          f"(cluster start-up {startup_s:.1f} s, not included)")
    print(f"speed-up: {result['speedup_median']:.2f}× (median; per round "
          f"{', '.join(f'{x:.2f}' for x in result['speedup_per_round'])}); "
          f"{result['speedup_with_startup']:.2f}× counting the start-up")
    print(f"cost: {t_seq / n:.3f} s per campaign, {1e3 * t_seq / impacts:.1f} ms per impact, "
          f"{size_mb / t_seq:.0f} MB/s per worker (wall, sequential)")
    print(f"CPU per campaign: {result['cpu_per_campaign_s_sequential']:.3f} s in one process, "
          f"{result['cpu_per_campaign_s_workers']:.3f} s in a worker")
    print(f"cores obtained (task CPU s per wall s): sequential {result['cores_sequential']}, "
          f"{args.workers} workers {result['cores_parallel']}")


if __name__ == "__main__":
    main()
