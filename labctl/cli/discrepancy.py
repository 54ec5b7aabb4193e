"""``labctl discrepancy``: where measured stiffness and the model disagree, and which effect the model misses."""

from __future__ import annotations

import argparse
from typing import Any

from labctl.cli.common import add_json, emit
from labctl.errors import InputError

BASELINE_CHOICES = ("tripp", "palmgren", "fit-ra0.2", "fit-ra0.03")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "discrepancy", help="find the physical effect the contact model misses in measured stiffness",
        description="Fit the baseline (Tripp's evaluation depth fitted) to measured stiffness, estimate the noise "
                    "from the repetitions, locate where model and data disagree, then name and add missing effects "
                    "(surface_roughness, end_effects, material_hardness, misalignment, setup_compliance) and "
                    "measurement-side errors (load_gain, load_offset, modulus_scale) until the residuals are "
                    "consistent with the noise (lack-of-fit test, level 0.01); what no library term explains gets "
                    "an unnamed empirical term. MEASURED: stiffness-table CSV files (columns "
                    "diameter_mm, contact_length_mm, rail_ra_um, load_n, stiffness_n_per_m, ...) or campaign "
                    "HDF5 files.")
    p.add_argument("measured", nargs="+", metavar="MEASURED", help="stiffness-table CSV or campaign .h5 file(s)")
    p.add_argument("--baseline", default="tripp", choices=BASELINE_CHOICES,
                   help="contact model the effects are added to (default tripp)")
    p.add_argument("--report", metavar="DIR", help="write plots, the JSON document and a summary into DIR")
    p.add_argument("--rig", metavar="FILE",
                   help="rig file whose K_setup the processing assumed (default: the rig stored in the campaign "
                        "files, else the shipped paper rig)")
    p.add_argument("--max-effects", type=int, default=8, metavar="N",
                   help="add at most N terms, physical and measurement-side (default 8)")
    add_json(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from labctl.discrepancy import run_files  # heavy (scipy, matplotlib): only when used
    from labctl.discrepancy.report import sources_of, summary_text, write_report
    from labctl.discrepancy.workflow import MAX_TERMS

    if not 0 <= args.max_effects <= MAX_TERMS:
        raise InputError(f"--max-effects {args.max_effects}: expected 0 to {MAX_TERMS}")
    result = run_files(args.measured, args.baseline, rig=args.rig, max_effects=args.max_effects)
    doc: dict[str, Any] = result.to_dict()
    doc["sources"] = [s.describe() for s in sources_of(args.measured)]  # SIMULATED for a twin campaign
    if args.report:
        files = write_report(result, args.report, doc, sources=args.measured)
        doc["report"] = [str(f) for f in files]
    emit(doc, args.json, lambda d: summary_text(d) + (f"\nreport: {args.report}" if args.report else ""))
    return 0
