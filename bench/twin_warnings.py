"""Warnings on clean twin campaigns: how many steps warn, and is each warning true (the twin's truth beside it)?

    python bench/twin_warnings.py [--seeds 1 2 3] [--hammer-level N]

Runs ``protocols/roller_stiffness.toml`` (the paper's roller-type-1 campaign, 3 repetitions × 11 steps) on the
default world for each seed (seed 1 is ``labctl demo``), reprocesses the file as ``labctl process --json`` does
and prints the steps with any warning, the warning, and the twin's per-roller stiffnesses at that step (relative
to their mean: a roller seated unlike the others is a true finding). ``--hammer-level N`` fixes the hammer at N
newtons instead of the technician's blow matched to the load (the twin's default, docs/simulator.md).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from drivers.sim.twin import RigTwin  # noqa: E402
from labctl.campaign import run_campaign  # noqa: E402
from labctl.reprocess import process_campaign  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--hammer-level", type=float, default=None, metavar="N")
    args = ap.parse_args(argv)
    truth: dict[tuple[int, float], list[float]] = {}  # (repetition's seating count, load) -> roller k's
    strike = RigTwin.strike

    def recording_strike(twin: RigTwin):
        if args.hammer_level is not None and twin.settings.peak_force_per_load > 0:
            twin.settings = replace(twin.settings, peak_force_n=args.hammer_level, peak_force_per_load=0.0)
        truth[(twin.rotations, round(twin.load_per_roller_n(), 1))] = twin.roller_stiffness_n_per_m()
        return strike(twin)

    RigTwin.strike = recording_strike  # the bench watches the hidden rig; the campaign runs as it would
    total = warned = 0
    hammer = f"fixed at {args.hammer_level:g} N" if args.hammer_level else "matched to the load (default)"
    print(f"# roller_stiffness.toml on the default world; hammer {hammer}\n")
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            truth.clear()
            path = Path(tmp) / f"run{seed}.h5"
            run_campaign(ROOT / "protocols" / "roller_stiffness.toml", out=path, seed=seed)
            steps = process_campaign(path).rows
            with_warning = [s for s in steps if s.result.warnings]
            total, warned = total + len(steps), warned + len(with_warning)
            print(f"seed {seed}: {len(with_warning)}/{len(steps)} steps warn")
            for s in with_warning:
                ks = min(truth.items(), key=lambda kv: (kv[0][0] != s.run, abs(kv[0][1] - s.load_n)))[1]
                mean = sum(ks) / 3
                rel = ", ".join(f"{100 * (k / mean - 1):+.1f} %" for k in ks)
                for w in s.result.warnings:
                    print(f"  run {s.run} step {s.step} ({s.load_n:.1f} N; twin's rollers {rel}): {w[:160]}")
    print(f"\nall: {warned}/{total} steps warn ({warned / total:.1%}; the acceptance: ≤ 1 in 20)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
