"""``labctl demo``: the roller-type-1 load sweep of the paper's §2.3 on the paper rig, model side."""

from __future__ import annotations

import argparse

import numpy as np

from labctl.cli.common import add_json, emit
from labctl.physics import (
    EQ5,
    ContactCase,
    ContactLaw,
    EmpiricalFit,
    SurfaceRoughness,
    TrippContact,
    load_rig,
    material,
    rig_modes,
    roller,
    roller_stiffness_from_bounce,
    static_load_rating_n,
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="roller type 1 on the paper rig: load steps, modes and stiffness vs models")
    p.add_argument("--out", help="directory for results")
    add_json(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    rig = load_rig()
    r, steel = roller(1), material("1.3505")
    case = ContactCase(r, steel, 0.2e-6)
    world = ContactLaw("tripp", 1.5e-3, (SurfaceRoughness(1.5),))
    cap = 0.3 * static_load_rating_n(r, steel)
    step = rig.loading.rods * rig.loading.spring_rate_n_per_m * 0.5 * rig.loading.thread_pitch_m / 3
    loads = np.arange(rig.preload_per_roller_n, cap + 1e-9, step)
    rows = []
    for f in loads:
        k_true = float(world.stiffness_n_per_m(case, f))
        modes = rig_modes(rig, k_true)
        k_back = roller_stiffness_from_bounce(rig, modes.bounce_hz)
        rows.append({"load_n": float(f), "bounce_hz": modes.bounce_hz, "tilt_hz": list(modes.tilt_hz),
                     "stiffness_n_per_m": k_back,
                     "tripp_n_per_m": float(TrippContact(r, steel).stiffness_n_per_m(f)),
                     "eq5_n_per_m": float(EmpiricalFit(EQ5, r.contact_length_m).stiffness_n_per_m(f))})

    def text(res: dict) -> str:
        lines = [f"roller type 1 on {rig.name}; load cap 30 % of C0 = {cap:.0f} N",
                 " load [N]  bounce [Hz]  tilt [Hz]   k [N/m]     Tripp [N/m]   Eq.5 [N/m]"]
        for s in res["steps"]:
            lines.append(f"{s['load_n']:8.1f}  {s['bounce_hz']:10.2f}  {s['tilt_hz'][0]:8.2f}  "
                         f"{s['stiffness_n_per_m']:.4e}  {s['tripp_n_per_m']:.4e}  {s['eq5_n_per_m']:.4e}")
        return "\n".join(lines)

    emit({"roller_type": 1, "steps": rows}, args.json, text)
    return 0
