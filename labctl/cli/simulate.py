"""``labctl simulate impacts``: hammer impacts on the simulated rig at one load, written as an impacts NPZ.

The twin is put directly at the requested load per roller, struck N times through the simulated DAQ and
hammer, and the truth it used (load, the three roller stiffnesses, bounce and tilt frequencies) is printed.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

from labctl.cli.common import add_json, emit
from labctl.errors import InputError

if TYPE_CHECKING:
    import numpy as np

    from drivers.interfaces import Rig

SAMPLE_RATE_HZ = 20_480.0
N_SAMPLES = 65_536
UM, MM = 1e-6, 1e-3
BALL_WORLD = "balls"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="the simulated rig (digital twin): synthetic impact data with known truth")
    ss = p.add_subparsers(dest="simulate_command", metavar="{impacts}")
    ss.required = True
    i = ss.add_parser("impacts", help="strike the twin at one load and write an impacts NPZ; print the truth")
    what = i.add_mutually_exclusive_group(required=True)
    what.add_argument("--roller-type", type=int, metavar="N", help="roller type of the catalogue (Table 1)")
    what.add_argument("--ball-mm", type=float, metavar="D",
                      help="a steel ball of diameter D mm: Hertz contacts (world 'balls' unless --world names another "
                           "world with ball contacts)")
    i.add_argument("--load-n", type=float, required=True, metavar="F", help="load per roller, N")
    i.add_argument("--impacts", type=int, default=3, help="number of impacts (default 3)")
    i.add_argument("--world", help="world scenario: a TOML file or a shipped name (default: default)")
    i.add_argument("--hammer-level", type=float, metavar="N",
                   help="the hammer's mean peak force, N (default: the technician matches the blow to the load, "
                        "the world's [instruments] peak_force_per_load × load within peak_force_min_n..peak_force_n, "
                        "by default 1.0 × load within 60..250 N)")
    i.add_argument("--seed", type=int, help="random seed (default: fresh; the one used is printed)")
    i.add_argument("--rail-ra-um", type=float, default=0.2, help="rail roughness Ra, µm (default 0.2)")
    i.add_argument("--rail-material", help="rail material (default: the catalogue's bearing steel)")
    i.add_argument("--rig", help="rig TOML file (default: the paper's rig)")
    i.add_argument("--out", help="impacts NPZ file to write (a name ending in .npz); without it only the truth is "
                   "printed")
    add_json(i)
    i.set_defaults(func=run_impacts)


def run_impacts(args: argparse.Namespace) -> int:
    from labctl.data.schema import MAX_RA_UM

    if args.impacts < 1:
        raise InputError(f"--impacts {args.impacts}: expected at least 1")
    if not 0 < args.rail_ra_um <= MAX_RA_UM:
        raise InputError(f"--rail-ra-um {args.rail_ra_um!r}: expected a roughness in (0, {MAX_RA_UM:g}] µm")
    out = None if args.out is None else Path(args.out)
    if out is not None and out.suffix.lower() != ".npz":
        raise InputError(f"--out {out}: an impacts file is an NPZ; expected a name ending in .npz "
                         f"(e.g. {out.with_suffix('.npz')})")
    if out is not None and not out.parent.is_dir():
        raise InputError(f"--out {out}: directory {out.parent} does not exist")
    if args.hammer_level is not None and not args.hammer_level > 0:
        raise InputError(f"--hammer-level {args.hammer_level!r}: expected a positive peak force in N")
    from dataclasses import replace

    import numpy as np

    from drivers.sim import twin_of
    from labctl.backends import make_rig
    from labctl.physics import ContactCase, material, roller
    from labctl.physics.materials import BEARING_STEEL
    from labctl.physics.world import ball, load_world

    rail = material(args.rail_material or BEARING_STEEL)
    world = args.world
    if args.ball_mm is not None:
        if not args.ball_mm > 0:
            raise InputError(f"--ball-mm {args.ball_mm!r}: expected a positive diameter in mm")
        world = world or BALL_WORLD
        baseline = load_world(world).law.baseline
        if baseline != "hertz":
            raise InputError(f"--ball-mm with --world {world}: that world's contacts are '{baseline}' (rollers), not "
                             f"balls; use --world {BALL_WORLD} or a world whose baseline model is 'hertz'")
        element = ball(args.ball_mm * MM, material(BEARING_STEEL))
    else:
        element = roller(args.roller_type)
    rig = make_rig("sim", case=ContactCase(element, rail, args.rail_ra_um * UM), rig=args.rig, world=world,
                   seed=args.seed)
    twin = twin_of(rig)
    if args.hammer_level is not None:
        twin.settings = replace(twin.settings, peak_force_n=args.hammer_level, peak_force_per_load=0.0)
    if not args.load_n >= twin.preload_n:
        raise InputError(f"--load-n {args.load_n:g}: below the preload {twin.preload_n:.1f} N per roller "
                         "(the upper disc's weight)")
    twin.set_load_per_roller(args.load_n)
    fs, force, accel, channels = strike_series(rig, args.impacts)
    if out is not None:
        np.savez(out, fs=np.float64(fs), force=force, accel=accel, channels=np.array(channels, dtype=np.str_))
    result: dict[str, Any] = {**twin.truth(), "seed": twin.seed, "world": rig.description["world"],
                              "hammer_level_n": twin.hammer_level_n(), "out": None if out is None else str(out)}
    emit(result, args.json, _text)
    return 0


def strike_series(rig: Rig, impacts: int) -> tuple[float, np.ndarray, np.ndarray, tuple[str, ...]]:
    """Arm, strike and acquire ``impacts`` times at the paper's rate and length; stacked force and accel."""
    import numpy as np

    from drivers.interfaces import TriggerSpec

    fs = rig.daq.configure(SAMPLE_RATE_HZ, N_SAMPLES)
    records = []
    for _ in range(impacts):
        rig.daq.arm(TriggerSpec())
        rig.hammer.strike()
        records.append(rig.daq.acquire(timeout_s=5.0))
    force = np.stack([r.force_n for r in records])
    accel = np.stack([r.accel_m_per_s2 for r in records])
    return fs, force, accel, records[0].channels


def _text(r: dict[str, Any]) -> str:
    k = ", ".join(f"{v:.4e}" for v in r["roller_stiffness_n_per_m"])
    t = r["tilt_hz"]
    wrote = f"wrote {r['out']}" if r["out"] else "no file written (--out FILE.npz keeps the impacts)"
    return (f"{wrote}  (world {r['world']}, seed {r['seed']}, hammer {r['hammer_level_n']:.0f} N)\n"
            f"load {r['load_n']:.1f} N per roller; roller stiffness {k} N/m\n"
            f"bounce {r['bounce_hz']:.2f} Hz   tilt {t[0]:.2f} / {t[1]:.2f} Hz")
