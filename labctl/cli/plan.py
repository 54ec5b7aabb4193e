"""``labctl plan``: which specimen and which loads to measure next to separate the candidate effects."""

from __future__ import annotations

import argparse

from labctl.cli.common import add_json, emit, say
from labctl.errors import InputError


def _budget(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number of load steps") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value}: expected at least 1 load step")
    return value


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plan", help="recommend the next measurements that would best separate the candidate effects",
        description="Run the discrepancy workflow on the data so far, take the candidate models still in play "
                    "(the final model, the final model plus or minus one term, the unnamed empirical term) and "
                    "rank every catalogue roller type on Ra 0.2 and 0.03 µm rails, at loads the rig's knobs "
                    "reach below the protocol's C0 cap, by the expected information the new points would give "
                    "(docs/planning.md). 'enough' is true when no candidate measurement could bring a rival "
                    "model decisively ahead of the verdict.")
    p.add_argument("measured", nargs="+", metavar="MEASURED", help="stiffness-table CSV or campaign .h5 file(s)")
    p.add_argument("--candidates", default="all", metavar="all|NAME,...",
                   help="terms whose models compete (default all: the physical effects and the measurement-side "
                        "terms)")
    p.add_argument("--budget-steps", type=_budget, default=5, metavar="N",
                   help="load steps (hit at) per recommended mounting (default 5)")
    p.add_argument("--rig", metavar="FILE", help="rig file: preload, load per knob degree, K_setup "
                                                 "(default: the shipped paper rig)")
    p.add_argument("--protocol", default="roller_stiffness", metavar="NAME|FILE",
                   help="protocol whose loading rules apply: knob step, C0 cap (default roller_stiffness)")
    add_json(p)
    p.set_defaults(func=run)


def _refuse_ball_campaigns(paths: list[str]) -> None:
    """The planner ranks roller measurements: a campaign of ball specimens would enter as rollers whose
    contact length is the ball's diameter. Refused, naming the file and series."""
    from labctl.storage import CampaignReader

    for path in paths:
        try:
            with open(path, "rb") as fh:
                if fh.read(8) != b"\x89HDF\r\n\x1a\n":
                    continue  # a stiffness table (CSV): rollers by its columns
        except OSError:
            continue  # the reader below names a missing file
        with CampaignReader(path) as reader:
            balls = [s for s in reader.series_indices() if reader.specimen(s).kind == "ball"]
        if balls:
            raise InputError(f"{path}: series {', '.join(map(str, balls))} are balls (Hertz point contacts); the "
                             "planner ranks roller measurements: leave ball campaigns out (they calibrate the rig: "
                             "labctl calibrate)")


def run(args: argparse.Namespace) -> int:
    from labctl.discrepancy import load_points  # heavy (scipy): only when used
    from labctl.discrepancy.data import campaign_setup_stiffness
    from labctl.physics.rig_config import load_rig
    from labctl.planning import parse_candidates, plan_measurements
    from labctl.protocol import load_protocol

    _refuse_ball_campaigns(args.measured)
    candidates = parse_candidates(args.candidates)
    rig = load_rig(args.rig)
    protocol = load_protocol(args.protocol)
    if not any(s.kind == "roller" for s in protocol.specimens):
        raise InputError(f"--protocol {args.protocol}: expected a roller protocol (its C0 cap rules the loads)")
    k_setup = rig.setup_stiffness_n_per_m if args.rig else campaign_setup_stiffness(args.measured)
    points = load_points(args.measured)
    if not args.json:
        say(f"planning: scoring candidate rollers, rails and loads for {', '.join(args.measured)} (up to a minute)...")
    plan = plan_measurements(points, setup_stiffness_n_per_m=k_setup, candidates=candidates,
                             budget_steps=args.budget_steps, rig=rig, protocol=protocol)
    emit(plan.to_dict(), args.json, lambda _d: plan.summary_text())
    return 0
