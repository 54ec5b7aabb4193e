"""How often do the candidates a verdict lists hold the truth? The top three (what an "unexplained" verdict lists)
and the smallest set whose stated probabilities reach 0.9 (a 90 % credible set), with its mean size.

The top-1 asks one name to be right; where the library's laws differ from the truth's no method measured here ranks
it first nine times in ten (docs/discrepancy.md, Limits). A set of candidates can still mean what it says: a 90 %
set that holds the truth 90 % of the time is a calibrated statement whatever the top-1. This bench reads:

- the files ``bench/discrepancy_eval.py --out F`` wrote, each dataset decided again by the workflow's own rule on
  its stored evidence (``discrepancy_rescale.rule`` with the workflow's settings);
- with ``--oracle F``, the files ``bench/oracle_unseen.py --out F`` wrote: the oracle's class posterior with the
  world's own law known and unseen.

Per file: the library truths of size ≥ 3σ, the worlds outside the library, and all datasets, each with the share
whose truth is first, in the top three, in the 90 % set (95 % Wilson intervals), and the set's mean size.

    python bench/discrepancy_sets.py [EVAL.json ...] [--oracle UNSEEN.json ...]
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from discrepancy_rescale import WORKFLOW_RULE, rule
from oracle_report import count_share, library_big
from scipy.special import softmax

LEVEL = 0.9
"""The credible set's stated mass."""

Ranked = list[tuple[str, float]]


def credible_set(probs: Ranked, level: float = LEVEL) -> list[str]:
    """The fewest most probable candidates whose probabilities sum to ``level`` or more (all, if they never do)."""
    out, mass = [], 0.0
    for name, p in probs:
        out.append(name)
        mass += p
        if mass >= level:
            break
    return out


def from_log_posterior(post: dict[str, float]) -> Ranked:
    """Class probabilities, most probable first, from an unnormalised ln posterior."""
    probs = softmax(list(post.values()))
    return sorted(zip(post, map(float, probs), strict=True), key=lambda kv: -kv[1])


def line(label: str, cases: Iterable[tuple[Ranked, str]]) -> str:
    """One row: first, in the top three, in the 90 % set, and the set's mean size."""
    cases = list(cases)
    n = len(cases)
    first = sum(probs[0][0] == truth for probs, truth in cases)
    three = sum(truth in [name for name, _ in probs[:3]] for probs, truth in cases)
    sets = [credible_set(probs) for probs, _ in cases]
    held = sum(truth in s for s, (_, truth) in zip(sets, cases, strict=True))
    size = sum(len(s) for s in sets) / n if n else float("nan")
    shares = " | ".join(count_share(k, n) for k in (first, three, held))
    return f"| {label} | {n} | {shares} | {size:.1f} |"


def groups(rows: list[tuple[Ranked, str, bool, bool]]) -> list[tuple[str, list[tuple[Ranked, str]]]]:
    """The library truths ≥ 3σ, the outside effects, and every dataset, from (ranked, truth, big, outside) rows."""
    return [("library ≥ 3σ", [(p, t) for p, t, big, out in rows if big and not out]),
            ("outside", [(p, t) for p, t, _, out in rows if out]),
            ("all", [(p, t) for p, t, _, _ in rows])]


def workflow_rows(results: list[dict[str, Any]]) -> list[tuple[Ranked, str, bool, bool]]:
    """Each dataset decided by the workflow's rule on its stored evidence."""
    decide = rule(**WORKFLOW_RULE)
    return [(decide(r), r["truth_name"], r["truth_name"] not in ("none", "unlisted") and r["size_sigma"] >= 3,
             r["truth_name"] == "unlisted") for r in results]


def oracle_rows(results: list[dict[str, Any]], key: str) -> list[tuple[Ranked, str, bool, bool]]:
    """Each world's oracle posterior (``post`` or ``post_unseen``) as probabilities."""
    return [(from_log_posterior(r[key]), r["truth"], library_big(r), r["truth"] == "unlisted") for r in results]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="*", type=Path, help="results saved by discrepancy_eval.py --out")
    ap.add_argument("--oracle", nargs="*", type=Path, default=[], help="results saved by oracle_unseen.py --out")
    args = ap.parse_args(argv)
    print(f"| who, file, datasets | n | truth first | truth in the top three | truth in the {LEVEL:.0%} set "
          "| mean set size |")
    print("|---|---|---|---|---|---|")
    tables = [(f"workflow, {p.name}", workflow_rows(json.loads(p.read_text()))) for p in args.files]
    for path in args.oracle:
        results = json.loads(path.read_text())
        for scale in sorted({r["scale"] for r in results}):
            at = [r for r in results if r["scale"] == scale]
            tables += [(f"oracle law {which}, {path.name} {scale:g}x", oracle_rows(at, key))
                       for which, key in (("known", "post"), ("unseen", "post_unseen"))]
    for who, rows in tables:
        for label, cases in groups(rows):
            print(line(f"{who}, {label}", cases))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
