"""A campaign without a load cell: the spring curve's loads against the load cell's, same seed, same rig.

World ``springs`` (the default world's physics with real spring stacks: per-rod rates, +4 % progressive at ten
half turns, friction hysteresis, 5-25° first-turn slack, up to 10° of fresh nut slack after every re-seating).

1. ``characterise``: protocols/spring_characterisation.toml on the twin (seed ``--char-seed``), a load cell
   under the disc; the curve is fitted and written into a copy of the paper rig as ``[springs]``.
2. Two campaigns of the same protocol (roller type 1, Ra 0.2 µm, 440 N in half turns, ``--impacts`` impacts,
   ``--reps`` repetitions) with the same seed: one reading the load cell, one with ``load_source = "springs"``.
   The same seed gives both the same seatings and blows, so each step's stiffness is the same; what differs is
   the load each step is recorded at.

Printed per step: the load-cell load, the springs load ± its 1-σ, their difference in σ, and the springs
campaign's stiffness against the load-cell campaign's stiffness-vs-load curve (log-log interpolation per
repetition) at the springs load. The summary gives the largest stiffness deviation, the share of load
differences within 1 and 2 σ, and the largest. Run: ``PYTHONPATH=. python bench/springs_campaign.py``.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from labctl.backends import make_rig
from labctl.calibration.spring_run import characterise, load_spring_protocol
from labctl.calibration.springs import fit_spring_curve, rig_text_with_springs
from labctl.campaign import run_campaign
from labctl.physics import ContactCase, load_rig, material, roller
from labctl.protocol import parse_protocol
from labctl.storage import CampaignReader, campaign_stiffness_points

PROTOCOL = """
[protocol]
name = "springs_bench"
[specimen]
roller_type = 1
rail_ra_um = 0.2
knob_step_deg = 180.0
[acquisition]
impacts_per_step = {impacts}
[loading]
{extra}
[repetitions]
count = {reps}
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--char-seed", type=int, default=11)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--impacts", type=int, default=2)
    a = ap.parse_args()
    world = "springs"
    case = ContactCase(roller(1), material("1.3505"), 0.2e-6)
    rig = make_rig("sim", case=case, world=world, seed=a.char_seed)
    curve = fit_spring_curve(characterise(rig, load_spring_protocol("protocols/spring_characterisation.toml"), 3))
    print(f"curve: preload {curve.preload_n:.2f} N, rate {curve.rate_n_per_deg:.5f} N/° (nominal "
          f"{load_rig().load_per_knob_degree_n:.5f}), curvature {curve.curvature_n_per_deg2:.3g} N/°², "
          f"hysteresis {curve.hysteresis_n:.2f} N, slack {curve.slack_deg:.1f}°, scatter {curve.residual_std_n:.2f} N")
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        rig_file = d / "rig.toml"
        rig_file.write_text(rig_text_with_springs(Path(load_rig().source).read_text(encoding="utf-8"), "rig",
                                                  curve, "bench"), encoding="utf-8")
        files = {}
        for name, extra in (("cell", ""), ("springs", 'load_source = "springs"')):
            proto = parse_protocol(PROTOCOL.format(impacts=a.impacts, reps=a.reps, extra=extra), f"{name}.toml")
            files[name] = d / f"{name}.h5"
            status = run_campaign(proto, out=files[name], world=world, seed=a.seed, rig=rig_file).status
            assert status == "complete", status
        cell, spr = (campaign_stiffness_points(files[n]) for n in ("cell", "springs"))
        with CampaignReader(files["springs"]) as reader:
            opened = [s for i in reader.series_indices() for r in reader.runs(i) for s in r.steps]
    print(f"{len(spr)} steps; the springs campaign's steps record load_source = "
          f"{sorted({str(s.attrs.get('load_source')) for s in opened})}")
    print(f"{'rep':>3} {'cell N':>8} {'springs N':>10} {'σ N':>5} {'Δ/σ':>6} {'Δk %':>7}")
    dk, z = [], []
    for rep in sorted({p.repetition for p in cell}):
        a_pts = [p for p in cell if p.repetition == rep]
        b_pts = [p for p in spr if p.repetition == rep]
        fa, ka = np.log([p.load_n for p in a_pts]), np.log([p.stiffness_n_per_m for p in a_pts])
        for pa, pb in zip(a_pts, b_pts, strict=True):
            k_cell = np.exp(np.interp(np.log(pb.load_n), fa, ka))
            dk.append(100 * (pb.stiffness_n_per_m / k_cell - 1))
            z.append((pb.load_n - pa.load_n) / pb.load_std_n)
            print(f"{rep:3d} {pa.load_n:8.2f} {pb.load_n:10.2f} {pb.load_std_n:5.2f} {z[-1]:+6.2f} {dk[-1]:+7.3f}")
    z_abs = np.abs(z)
    print(f"stiffness vs load: largest deviation {np.max(np.abs(dk)):.3f} % (acceptance: within 2 %)")
    print(f"load differences: {np.mean(z_abs < 1):.0%} within 1 σ, {np.mean(z_abs < 2):.0%} within 2 σ, "
          f"largest {z_abs.max():.2f} σ")


if __name__ == "__main__":
    main()
