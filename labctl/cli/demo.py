"""``labctl demo``: the README's main job — the roller-type-1 campaign (paper §2.3) on the simulated rig."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from labctl.cli.common import add_json, emit

PROTOCOL = "roller_stiffness"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="run the roller-type-1 campaign on the simulated rig and compare with models")
    p.add_argument("--out", default="labctl-demo",
                   help="directory for campaign.h5 and stiffness.csv (default ./labctl-demo)")
    p.add_argument("--force", action="store_true", help="overwrite a campaign.h5 already in that directory")
    p.add_argument("--seed", type=int, default=1, help="seed of the simulated rig (default 1)")
    p.add_argument("--world", help="world scenario for the simulated rig (default: Tripp + surface roughness)")
    p.add_argument("--quiet", action="store_true", help="no progress display")
    add_json(p)
    p.set_defaults(func=run)


def summarise(curves: list[Any], case: Any) -> list[dict[str, float]]:
    """Per load step over the repetitions: mean load and stiffness, spread (max-min)/mean, and the models."""
    import numpy as np

    from labctl.physics.references import reference_curves

    n = min(len(c.load_n) for c in curves)
    loads = np.array([c.load_n[:n] for c in curves])
    k = np.array([c.stiffness_n_per_m[:n] for c in curves])
    mean_load, mean_k = loads.mean(axis=0), k.mean(axis=0)
    refs = reference_curves(case, "roller", mean_load)
    return [{"step": i + 1, "load_n": float(mean_load[i]), "stiffness_n_per_m": float(mean_k[i]),
             "spread": float((k[:, i].max() - k[:, i].min()) / mean_k[i]),
             "tripp_n_per_m": float(refs["tripp"][i]), "eq5_n_per_m": float(refs["fit-ra0.2"][i]),
             "vs_eq5": float(mean_k[i] / refs["fit-ra0.2"][i] - 1.0)} for i in range(n)]


def run(args: argparse.Namespace) -> int:
    from labctl.campaign import run_campaign
    from labctl.cli.progress import ProgressPrinter
    from labctl.errors import InputError
    from labctl.protocol import load_protocol
    from labctl.stiffness_table import write_stiffness_table
    from labctl.storage.outputs import output_folder
    from labctl.storage.table import campaign_stiffness_points

    out = Path(args.out)
    path = out / "campaign.h5"
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: is a file; --out names a directory for campaign.h5 and stiffness.csv")
    if path.exists() and not args.force:
        raise InputError(f"{path}: a campaign is already there; use --force to overwrite it or choose another --out")
    protocol = load_protocol(PROTOCOL)
    output_folder("--out", out)
    path.unlink(missing_ok=True)
    subs = [] if args.quiet or args.json else [ProgressPrinter(sys.stderr)]
    outcome = run_campaign(protocol, out=path, backend="sim", seed=args.seed, world=args.world, subscribers=subs)
    if outcome.status != "complete" or not outcome.curves:
        raise RuntimeError(f"demo campaign ended {outcome.status}: {outcome.message}")
    csv = out / "stiffness.csv"
    write_stiffness_table(csv, campaign_stiffness_points(path))  # the stored step results, as taken
    steps = summarise(outcome.curves, protocol.specimens[0].case())
    result = {"campaign": str(path), "csv": str(csv), "repetitions": len(outcome.curves), "steps": steps}

    def text(r: dict[str, Any]) -> str:
        lines = [f"roller type 1 on Ra 0.2 µm rails, {r['repetitions']} repetitions → {r['campaign']}, {r['csv']}",
                 " step  load [N]   k mean [N/m]  spread   Tripp [N/m]   Eq. 5 [N/m]   k/Eq.5-1"]
        for s in r["steps"]:
            lines.append(f" {s['step']:4d} {s['load_n']:9.1f}   {s['stiffness_n_per_m']:.4e}  {s['spread']:6.2%}"
                         f"   {s['tripp_n_per_m']:.4e}    {s['eq5_n_per_m']:.4e}   {s['vs_eq5']:+7.2%}")
        return "\n".join(lines)

    emit(result, args.json, text)
    return 0
