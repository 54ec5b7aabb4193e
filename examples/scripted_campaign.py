"""Run a short campaign on the simulated rig from a script, watch it through events, and export the table.

    python examples/scripted_campaign.py [OUT_DIR]
"""

from __future__ import annotations

import sys
from pathlib import Path

from labctl import events as ev
from labctl.campaign import run_campaign
from labctl.reprocess import process_campaign
from labctl.stiffness_table import write_stiffness_table


def on_event(event: ev.Event) -> None:
    """Print each identified step; a script can react to any event type the same way."""
    if isinstance(event, ev.StepProcessed):
        print(f"step {event.position.step}: {event.load_n:6.1f} N  bounce {event.bounce_hz:7.2f} Hz  "
              f"k {event.roller_stiffness_n_per_m:.4e} N/m")
    elif isinstance(event, ev.ImpactRejected):
        print(f"  impact rejected: {', '.join(event.reasons)}")


def main(out_dir: str = "example-out") -> int:
    out = Path(out_dir)
    out.mkdir(exist_ok=True)
    path = out / "quick_check.h5"
    path.unlink(missing_ok=True)
    outcome = run_campaign("quick_check", out=path, backend="sim", seed=7, subscribers=[on_event])
    print(f"campaign {outcome.status}: {outcome.path}")
    points = process_campaign(path).points
    write_stiffness_table(out / "stiffness.csv", points)
    print(f"{len(points)} stiffness points → {out / 'stiffness.csv'}")
    return 0 if outcome.status == "complete" else 1


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
