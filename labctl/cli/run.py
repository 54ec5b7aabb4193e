"""``labctl run``: an unattended campaign with a progress display; Ctrl-C stops cleanly and leaves a resumable file."""

from __future__ import annotations

import argparse
import signal
import sys
from typing import TYPE_CHECKING

from labctl.cli.common import add_json, emit

if TYPE_CHECKING:
    from labctl.engine import RunControl


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run a protocol on the simulated or real rig, writing a campaign file")
    p.add_argument("protocol", metavar="PROTOCOL", help="protocol TOML file (or a shipped name: quick_check)")
    p.add_argument("--backend", choices=("sim", "hw"), default="sim", help="simulated rig or hardware (default sim)")
    p.add_argument("--out", default="campaign.h5", help="campaign file to write (default campaign.h5)")
    p.add_argument("--resume", action="store_true", help="continue an interrupted campaign file after its last impact")
    p.add_argument("--world", help="world scenario TOML for the simulated rig (hidden effects)")
    p.add_argument("--seed", type=int, help="random seed for the simulated rig")
    p.add_argument("--rig", help="rig TOML file (default: the paper's rig)")
    p.add_argument("--devices", help="devices TOML file for --backend hw")
    p.add_argument("--operator", metavar="FILE.toml",
                   help="scripted operator: verdicts on chosen impacts ([[review]] series/run/step/attempt, "
                        "verdict accept|reject, reason) and prompt answers ([answers]); see docs/storage.md")
    p.add_argument("--adaptive", action="store_true",
                   help="after each repetition's base steps, add the load steps the planner ranks highest for the "
                        "mounted specimen (why each was added is stored with the step; docs/planning.md)")
    p.add_argument("--budget-steps", type=int, metavar="N",
                   help="with --adaptive: extra load steps per repetition (default 5)")
    p.add_argument("--quiet", action="store_true", help="no progress display")
    add_json(p)
    p.set_defaults(func=run)


def install_sigint(control: RunControl) -> None:
    """First Ctrl-C: clean stop at the next safe point; a second one interrupts at once."""

    def handler(signum: int, frame: object) -> None:
        if control.stop_status:
            signal.signal(signal.SIGINT, signal.default_int_handler)
            raise KeyboardInterrupt
        sys.stderr.write("\nstopping after the current impact (Ctrl-C again to interrupt now)\n")
        control.stop()

    signal.signal(signal.SIGINT, handler)


def rails_of(protocol: str) -> dict[int, float]:
    """Series → the rails' Ra (m), so two series of one roller type on different rails are told apart."""
    from labctl.errors import LabctlError
    from labctl.protocol import load_protocol

    try:
        return {i: s.rail_ra_m for i, s in enumerate(load_protocol(protocol).specimens, start=1)}
    except LabctlError:  # the run itself reported what is wrong with the protocol
        return {}


def run(args: argparse.Namespace) -> int:
    from labctl.campaign import load_operator_script, run_campaign
    from labctl.cli.progress import ProgressPrinter
    from labctl.engine import RunControl
    from labctl.storage.outputs import check_outputs

    check_outputs([("--out", args.out)], [args.protocol, args.world, args.rig, args.devices, args.operator],
                  allow_campaign=True)
    operator = load_operator_script(args.operator) if args.operator else None
    control = RunControl()
    install_sigint(control)
    subs = [] if args.quiet or args.json else [ProgressPrinter(sys.stderr)]
    outcome = run_campaign(args.protocol, out=args.out, backend=args.backend, resume=args.resume, world=args.world,
                           seed=args.seed, rig=args.rig, devices=args.devices, operator=operator, subscribers=subs,
                           control=control, adaptive=args.adaptive, budget_steps=args.budget_steps)
    rails = rails_of(args.protocol)
    result = {"status": outcome.status, "path": outcome.path, "message": outcome.message,
              "runs": [{"series": c.series, "run": c.run, "specimen": c.specimen, "step": c.step.tolist(),
                        "rail_ra_m": rails.get(c.series), "load_n": c.load_n.tolist(),
                        "stiffness_n_per_m": c.stiffness_n_per_m.tolist()} for c in outcome.curves]}

    def text(r: dict) -> str:
        lines = [f"campaign {r['status']}: {r['path']}" + (f" ({r['message']})" if r["message"] else "")]
        for c in r["runs"]:
            rail = f" on rails Ra {c['rail_ra_m'] * 1e6:.3g} µm" if c["rail_ra_m"] is not None else ""
            lines.append(f"  series {c['series']} ({c['specimen']}{rail}) repetition {c['run']}: "
                         f"{len(c['load_n'])} steps")
        return "\n".join(lines)

    emit(result, args.json, text)
    return 0 if outcome.status == "complete" else (130 if outcome.status == "interrupted" else 1)


