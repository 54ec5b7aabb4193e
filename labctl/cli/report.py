"""``labctl report FILE.h5 --out DIR``: the paper's figures as PNG and SVG and a self-contained HTML page."""

from __future__ import annotations

import argparse
import re
from typing import Any

from labctl.cli.common import add_json, emit
from labctl.errors import InputError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("report", help="figures (Figs. 7, 8, 12/13, frequency vs load) and an HTML report")
    p.add_argument("file", metavar="FILE.h5", help="campaign file")
    p.add_argument("--out", required=True, metavar="DIR", help="folder for report.html, the figures and the CSV")
    p.add_argument("--frf-step", metavar="S:R:N",
                   help="the step whose FRF is shown, as series:run:step (default: series 1, first repetition, "
                        "highest load)")
    p.add_argument("--band", type=float, metavar="PCT",
                   help="verdict band in %% around Eq. 5/6 for rollers (default 10; balls against Hertz: 5)")
    add_json(p)
    p.set_defaults(func=run)


def _step(text: str | None) -> tuple[int, int, int] | None:
    if text is None:
        return None
    m = re.fullmatch(r"\s*(\d+):(\d+):(\d+)\s*", text)
    if not m:
        raise InputError(f"--frf-step {text!r}: expected series:run:step, e.g. 1:2:11")
    s, r, n = (int(g) for g in m.groups())
    return s, r, n


REPORT_NAMES = ("report.html", "stiffness.csv")
FIGURE_SUFFIXES = (".png", ".svg")


def _refuse_input_in_out(file: str, out: str) -> None:
    """The report writes report.html, stiffness.csv and *.png/*.svg into --out: never over the campaign file."""
    from pathlib import Path

    from labctl.storage.outputs import same_file

    inp, folder = Path(file), Path(out)
    if (inp.is_file() and folder.is_dir() and same_file(inp.parent, folder)
            and (inp.name in REPORT_NAMES or inp.suffix.lower() in FIGURE_SUFFIXES)):
        raise InputError(f"--out {out}: the report writes {inp.name} there, which is the input {file}; "
                         "choose another --out folder (an output never overwrites an input)")


def run(args: argparse.Namespace) -> int:
    from labctl.report import build_report

    if args.band is not None and not 0 < args.band < 100:
        raise InputError(f"--band {args.band:g}: expected a percentage between 0 and 100")
    band = None if args.band is None else args.band / 100
    _refuse_input_in_out(args.file, args.out)
    result = build_report(args.file, args.out, _step(args.frf_step), band).to_dict()
    emit(result, args.json, _text)
    return 0


def _text(r: dict[str, Any]) -> str:
    imp = r["impacts"]
    counts: dict[str, int] = {}
    for v in r["verdicts"]:
        counts[v["verdict"]] = counts.get(v["verdict"], 0) + 1
    lines = ["SIMULATED data (digital twin)"] if r["simulated"] else []
    lines += [f"report → {r['html']}", f"impacts: {imp['accepted']} accepted, {imp['rejected']} rejected"
             + (" (" + ", ".join(f"{k} {v}" for k, v in imp["by_reason"].items()) + ")" if imp["by_reason"] else "")]
    if counts:
        lines.append("verdict per step: " + ", ".join(f"{n} {k}" for k, n in counts.items()))
    lines += [f"  {f['name']}: {f['title']}" for f in r["figures"]]
    if r["csv"]:
        lines.append(f"stiffness table → {r['csv']}")
    return "\n".join(lines)
