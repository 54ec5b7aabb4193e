"""``labctl compare``: is the stiffness-vs-load difference between two groups significant beyond the
repetition scatter, at which loads and by how much (the paper's "no significant effect" as a command)."""

from __future__ import annotations

import argparse

from labctl.cli.common import add_json, emit


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("compare", help="is the stiffness difference between two groups of campaigns significant?")
    p.add_argument("group_a", metavar="GROUP_A",
                   help="campaign files, stiffness CSVs or folders (comma-separated), or an archive query with --db")
    p.add_argument("group_b", metavar="GROUP_B", help="the same for the second group")
    p.add_argument("--db", help="archive catalogue for groups given as queries (labctl archive index)")
    p.add_argument("--level", type=float, default=0.05,
                   help="family-wise test level over all loads (default 0.05)")
    p.add_argument("--unit", choices=("auto", "repetition", "campaign"), default="auto",
                   help="the replicate: each repetition (re-seating) or each campaign's mean curve; auto (default): "
                        "campaigns when both groups hold two or more, else repetitions")
    add_json(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from labctl.compare import compare_groups, load_group

    a = load_group(args.group_a, db=args.db, name="GROUP_A")
    b = load_group(args.group_b, db=args.db, name="GROUP_B")
    result = compare_groups(a, b, level=args.level, unit=args.unit)
    doc = {
        "level": result.level, "unit": result.unit, "replicates_a": result.replicates_a,
        "replicates_b": result.replicates_b,
        "significant": result.significant, "significant_loads_n": result.significant_loads_n,
        "test": "Welch t on ln k per load, Holm-adjusted over loads; simultaneous (Bonferroni) intervals",
        "loads": [{"load_n": d.load_n, "difference": d.difference, "interval": [d.low, d.high],
                   "p_value": d.p_value, "p_adjusted": d.p_adjusted, "significant": d.significant}
                  for d in result.loads],
    }
    emit(doc, args.json, _text)
    return 0


def _text(doc: dict) -> str:
    level = doc["level"]
    lines = [f"A: {doc['replicates_a']} {doc['unit']}s, B: {doc['replicates_b']}; test at family-wise level {level:g} "
             "over the loads below (Welch t on ln k, Holm-adjusted)"]
    lines.append("  load [N]   k_A/k_B − 1   simultaneous interval      p (adjusted)")
    for d in doc["loads"]:
        lo, hi = d["interval"]
        mark = "  significant" if d["significant"] else ""
        lines.append(f"  {d['load_n']:8.1f}   {100 * d['difference']:+9.2f} %   [{100 * lo:+7.2f}, {100 * hi:+7.2f}] %"
                     f"   {d['p_adjusted']:.3g}{mark}")
    if doc["significant"]:
        loads = ", ".join(f"{f:.0f}" for f in doc["significant_loads_n"])
        lines.append(f"significant difference at level {level:g}, at {len(doc['significant_loads_n'])} of "
                     f"{len(doc['loads'])} loads: {loads} N")
    else:
        widest = max(max(abs(d["interval"][0]), abs(d["interval"][1])) for d in doc["loads"])
        lines.append(f"no significant difference at level {level:g}: differences inside the intervals above "
                     f"(up to {100 * widest:.1f} %) cannot be told from the repetition scatter")
    return "\n".join(lines)
