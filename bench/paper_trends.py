"""Does the simulated rig reproduce the paper's §3 findings? Prints one row per finding: the paper's figure and
number, the twin's number, the tolerance and whether it holds.

Run as the paper ran it: roller types 1-9 on rails of Ra 0.2 and 0.03 µm, the protocol's load steps (half
turns from the preload up to the C0 cap), three repetitions with the rollers re-seated between them. Every one
of the 18 campaigns runs on the simulated rig and every step's stiffness is identified from its raw impacts, as
on the rig (``labctl.programme``: the campaigns spread over worker processes, or an existing Dask scheduler,
largest first; campaign i has seed ``--seed`` + i; each file is deleted once its curves are in hand). The last
lines give the wall time, the CPU seconds of each campaign and the load average, and from those CPU seconds
the wall time the same run would take on an idle machine with that many workers.

``--truth`` is the quick check: each step's stiffness from the twin's truth (the roller stiffness the bounce
frequency of the three seated rollers implies, what an ideal identification returns), except the reference
configuration (type 1, Ra 0.2 µm), still run as a campaign from raw impacts for its scatter.

    python bench/paper_trends.py [--raw | --truth] [--workers N | --scheduler ADDR] [--world default] [--seed 1]
                                 [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from labctl.backends import make_twin  # noqa: E402
from labctl.physics import EQ5, EQ6, ContactCase, EmpiricalFit, material, roller  # noqa: E402
from labctl.physics.rig import roller_stiffness_from_bounce  # noqa: E402
from labctl.physics.rig_config import load_rig  # noqa: E402
from labctl.physics.world import load_world  # noqa: E402
from labctl.programme import (  # noqa: E402
    PAPER_RAILS_RA_M,
    PAPER_TYPES,
    CampaignDone,
    paper_programme,
    paper_protocol_text,
    run_programme,
)

STEEL_TYPES = range(1, 8)
RAILS = {0.2e-6: EQ5, 0.03e-6: EQ6}
PER_LENGTH_AT = 150e3  # N/m: load per contact length where Fig. 10's curves are compared


@dataclass
class Curve:
    loads: np.ndarray  # mean load per step (N)
    k: np.ndarray  # (repetitions, steps) roller stiffness (N/m)


def protocol_for(type_id: int, rail_ra_m: float) -> str:
    return paper_protocol_text(type_id, rail_ra_m)


def truth_curve(type_id: int, rail_ra_m: float, world: str, seed: int) -> Curve:
    """The protocol's steps on the twin, three seatings; each step's stiffness as the bounce implies it."""
    from labctl.protocol.parse import parse_protocol

    proto = parse_protocol(protocol_for(type_id, rail_ra_m), "bench")
    spec, rig = proto.specimens[0], load_rig()
    twin = make_twin(load_world(world), spec.case(), rig, seed=seed)
    per_step = rig.load_per_knob_degree_n * spec.knob_step_deg
    loads = np.arange(rig.preload_per_roller_n, spec.max_load_n + 1e-9, per_step)
    ks = []
    for _ in range(proto.repetitions.count):
        twin.rotate_rollers()
        row = []
        for load in loads:
            twin.set_load_per_roller(float(load))
            row.append(roller_stiffness_from_bounce(rig, twin.truth()["bounce_hz"]))
        ks.append(row)
    return Curve(loads, np.array(ks))


def curve_of(done: CampaignDone) -> Curve:
    """A campaign's repetition curves on the steps every repetition identified (load: mean over repetitions)."""
    if not done.ok:
        raise RuntimeError(f"campaign {done.name} ended {done.status}: {done.message}")
    common = sorted(set.intersection(*(set(c.step.tolist()) for c in done.curves)))
    rows = [np.isin(c.step, common) for c in done.curves]
    k = np.array([c.stiffness_n_per_m[r] for c, r in zip(done.curves, rows, strict=True)])
    loads = np.array([c.load_n[r] for c, r in zip(done.curves, rows, strict=True)]).mean(axis=0)
    return Curve(loads, k)


@dataclass
class Timing:
    wall_s: float
    cpu_s: dict[str, float]  # per campaign
    workers: int
    load_average: tuple[float, float, float]


def raw_curves(pairs: list[tuple[int, float]], world: str, seed: int, tmp: Path, workers: int | None,
               scheduler: str | None) -> tuple[dict[tuple[int, float], Curve], Timing]:
    """Campaigns on the simulated rig for these (type, rail) pairs, identified from their raw impacts."""
    jobs = {(j_type, j_ra): job for job, (j_type, j_ra) in
            zip(paper_programme(tmp, seed=seed, world=world, keep_files=False),
                ((t, ra) for t in PAPER_TYPES for ra in PAPER_RAILS_RA_M), strict=True)}
    chosen = [jobs[p] for p in pairs]
    t0 = time.perf_counter()
    if len(chosen) == 1 and workers is None and not scheduler:
        workers = 0  # one campaign (--truth): no cluster to start
    done = run_programme(chosen, workers=workers, scheduler=scheduler)
    timing = Timing(time.perf_counter() - t0, {d.name: d.cpu_seconds for d in done},
                    workers if workers is not None else os.cpu_count() or 1, os.getloadavg())
    return {p: curve_of(d) for p, d in zip(pairs, done, strict=True)}, timing


def frequencies_at(load_n: float, world: str, seed: int) -> tuple[float, float]:
    """Type 1 on Ra 0.2 µm rails put at ``load_n``: three impacts identified by the processing (bounce, tilt)."""
    from drivers.sim import twin_of
    from labctl.backends import make_rig
    from labctl.cli.simulate import strike_series
    from labctl.processing import identify

    rig_config = load_rig()
    rig = make_rig("sim", case=ContactCase(roller(1), material("1.3505"), 0.2e-6), rig=rig_config, world=world,
                   seed=seed)
    twin_of(rig).set_load_per_roller(load_n)
    fs, force, accel, channels = strike_series(rig, 3)
    ident = identify(force, accel, fs, channels, rig_config)
    return float(ident.bounce_hz), float(np.mean(ident.tilt_hz))


def eq_deviation(curve: Curve, type_id: int, rail_ra_m: float) -> float:
    fit = EmpiricalFit(RAILS[rail_ra_m], roller(type_id).contact_length_m)
    return float(np.max(np.abs(curve.k.mean(axis=0) / fit.stiffness_n_per_m(curve.loads) - 1.0)))


def per_length_at(curve: Curve, type_id: int, p_n_per_m: float = PER_LENGTH_AT) -> float:
    """Stiffness per contact length (N/m²) at one load per length, interpolated log-log along the mean curve."""
    length = roller(type_id).contact_length_m
    k = np.exp(np.interp(np.log(p_n_per_m * length), np.log(curve.loads), np.log(curve.k.mean(axis=0))))
    return float(k / length)


def at_load(curve: Curve, load_n: float) -> float:
    return float(np.exp(np.interp(np.log(load_n), np.log(curve.loads), np.log(curve.k.mean(axis=0)))))


def findings(world: str, seed: int, raw: bool, tmp: Path, workers: int | None = None,
             scheduler: str | None = None) -> tuple[list[dict[str, object]], Timing]:
    pairs = [(t, ra) for t in range(1, 10) for ra in RAILS]
    curves, timing = raw_curves(pairs if raw else [(1, 0.2e-6)], world, seed, tmp, workers, scheduler)
    for type_id, ra in pairs:
        if (type_id, ra) not in curves:
            curves[type_id, ra] = truth_curve(type_id, ra, world, seed + type_id)
    rows: list[dict[str, object]] = []

    def row(finding: str, figure: str, paper: str, twin: str, tolerance: str, ok: bool) -> None:
        rows.append({"finding": finding, "figure": figure, "paper": paper, "twin": twin, "tolerance": tolerance,
                     "pass": bool(ok)})

    for ra, name, fig in ((0.2e-6, "Eq. 5", "Fig. 12"), (0.03e-6, "Eq. 6", "Fig. 13")):
        devs = {t: eq_deviation(curves[t, ra], t, ra) for t in STEEL_TYPES}
        worst = max(devs, key=lambda t: devs[t])
        row(f"steel types 1-7 on Ra {ra * 1e6:g} µm follow {name}", fig, "most points within ±10 %",
            f"worst type {worst}: {devs[worst]:.1%} (every step, mean of 3 repetitions)", "all steps ≤ 10 %",
            devs[worst] <= 0.10)
    lengths = [1, 7, 5, 6]  # D = 3 mm bearing steel, L_we 1.79 / 1.95 / 2.57 / 3.73 mm
    per_len = [per_length_at(curves[t, 0.2e-6], t) for t in lengths]
    falls = all(a > b for a, b in zip(per_len, per_len[1:], strict=False))
    gain = per_len[0] / per_len[-1] - 1
    row("stiffness per contact length falls with roller length", "Fig. 10a",
        "clear decrease (end effects), all within Eq. 5's ±10 %",
        " > ".join(f"{v / 1e10:.3f}" for v in per_len) + f" e10 N/m² (types {lengths}); shortest +{gain:.1%}",
        "monotonic, shortest 3-20 % above longest", falls and 0.03 <= gain <= 0.20)
    diam = [2, 3, 4]  # D 1.5 / 6 / 9 mm
    per_d = [per_length_at(curves[t, 0.2e-6], t) for t in diam]
    row("stiffness per length falls with roller diameter (lengths differ too)", "Fig. 10b",
        "decrease with D (no definite conclusion)",
        " > ".join(f"{v / 1e10:.3f}" for v in per_d) + " e10 N/m² (D 1.5 / 6 / 9 mm)", "monotonic",
        per_d[0] > per_d[1] > per_d[2])
    si = [per_length_at(curves[8, 0.2e-6], 8, p) / per_length_at(curves[5, 0.2e-6], 5, p) - 1
          for p in (30e3, 150e3)]
    row("Si3N4 stiffer than bearing steel of the same length", "Fig. 11a", "stiffer (higher E*)",
        f"type 8 vs 5 per length: +{si[0]:.1%} at 30 N/mm, +{si[1]:.1%} at 150 N/mm", "> +3 % at both",
        min(si) > 0.03)
    top = 440.0
    ss_rough = at_load(curves[9, 0.2e-6], top) / at_load(curves[1, 0.2e-6], top) - 1
    ss_smooth = at_load(curves[9, 0.03e-6], top) / at_load(curves[1, 0.03e-6], top) - 1
    row("stainless stiffer than bearing steel, less so on mirror rails", "Fig. 11b",
        "considerably stiffer on Ra 0.2; difference reduced on Ra 0.03",
        f"type 9 vs 1 at {top:g} N: {ss_rough:+.1%} (Ra 0.2), {ss_smooth:+.1%} (Ra 0.03)",
        "≥ +5 % on Ra 0.2, smaller on Ra 0.03", ss_rough >= 0.05 and ss_smooth < ss_rough)
    bounce, tilt = frequencies_at(top, world, seed)
    row("type 1 bounce frequency at 440 N", "Fig. 7", "748 Hz", f"{bounce:.1f} Hz (3 impacts, identified)",
        "± 0.5 %", abs(bounce / 748.0 - 1) <= 0.005)
    row("type 1 tilt frequency at 440 N", "Fig. 7", "584 Hz", f"{tilt:.1f} Hz (3 impacts, identified)",
        "± 0.5 %", abs(tilt / 584.0 - 1) <= 0.005)
    ref = curves[1, 0.2e-6]
    spread = (ref.k.max(axis=0) - ref.k.min(axis=0)) / ref.k.mean(axis=0)
    sigma_top = float(ref.k[:, -1].std(ddof=1))
    row("repeatability of the reference roller (type 1, Ra 0.2)", "Fig. 8 / §3.1",
        "spread < 5 % at low load, < 1 % high (σ 5e4 N/m)",
        f"spread {spread[0]:.2%} at {ref.loads[0]:.0f} N, {spread[-1]:.2%} at {ref.loads[-1]:.0f} N "
        f"(σ {sigma_top:.2g} N/m)", "≤ 5 % low, ≤ 1 % high, σ 1e4-2e5",
        spread[0] <= 0.05 and spread[-1] <= 0.01 and 1e4 <= sigma_top <= 2e5)
    return rows, timing


def idle_wall_s(cpu_s: list[float], workers: int) -> float:
    """The campaigns' CPU seconds scheduled largest first on ``workers`` idle cores (what the runner does)."""
    busy = [0.0] * max(1, workers)
    for c in sorted(cpu_s, reverse=True):
        busy[busy.index(min(busy))] += c
    return max(busy)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--world", default="default")
    ap.add_argument("--seed", type=int, default=1)
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--raw", action="store_true", default=True,
                      help="every type and rail from raw impacts: 18 campaigns (the default)")
    mode.add_argument("--truth", dest="raw", action="store_false",
                      help="the twin's truth for all but the reference campaign (quick)")
    where = ap.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None, metavar="N",
                       help="local Dask cluster of N worker processes (default: one per CPU; 0: in this process)")
    where.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler (shared /tmp)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        rows, timing = findings(args.world, args.seed, args.raw, Path(tmp), args.workers, args.scheduler)
    cpu = list(timing.cpu_s.values())
    where = args.scheduler or (f"{timing.workers} local worker processes" if timing.workers else "this process")
    summary = {"campaigns": len(cpu), "wall_s": timing.wall_s, "cpu_s": timing.cpu_s, "where": where,
               "load_average": timing.load_average, "idle_wall_estimate_s": idle_wall_s(cpu, max(1, timing.workers))}
    if args.json:
        print(json.dumps({"rows": rows, "timing": summary}))
    else:
        print(f"{'finding':<66} {'figure':<14} {'paper':<54} {'twin':<74} {'tolerance':<38} pass")
        for r in rows:
            print(f"{r['finding']:<66} {r['figure']:<14} {r['paper']:<54} {r['twin']:<74} {r['tolerance']:<38} "
                  f"{'yes' if r['pass'] else 'NO'}")
        print(f"{len(cpu)} campaigns from raw impacts on {where}: {timing.wall_s:.1f} s wall, "
              f"{sum(cpu):.1f} s CPU in the campaigns (largest {max(cpu):.1f} s); load average "
              f"{' '.join(f'{x:.1f}' for x in timing.load_average)} on {os.cpu_count()} CPUs")
        per = " ".join(f"{k.removeprefix('paper_')} {v:.1f}" for k, v in timing.cpu_s.items())
        print(f"per campaign CPU s: {per}")
        print(f"idle estimate: these CPU seconds, largest first on {max(1, timing.workers)} idle workers: "
              f"{summary['idle_wall_estimate_s']:.1f} s (plus the cluster's start-up)")
    return 0 if all(r["pass"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
