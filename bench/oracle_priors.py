"""The oracle's posterior with the workflow's priors: would exact laws with another prior state reliable probabilities?

Reads what ``bench/oracle_ceiling.py --out F`` wrote (each world's ln posterior of every truth class under the
judge's own prior) and decides each world again with the workflow's class priors (``PRIOR_MASS``, split evenly
within each class as the workflow splits them, renormalised over the judge's classes) in place of the judge's:
ln p'(c | D) = ln p(c | D) − ln prior_judge(c) + ln prior_workflow(c). Prints the reliability lines of both
(stated top probability against share right, 95 % Wilson intervals). With the judge's prior the oracle's
probabilities are right as stated, up to its integral; what is left with the workflow's is the prior's part.

    python bench/oracle_priors.py F.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
from oracle_ceiling import hypotheses, logsumexp
from oracle_report import reliability

from labctl.discrepancy.posterior import explanations, log_prior


def judge_log_prior() -> dict[str, float]:
    """ln prior of each truth class under the judge (its sub-hypotheses' priors summed)."""
    by: dict[str, list[float]] = {}
    for hyp in hypotheses():
        by.setdefault(hyp.label, []).append(hyp.log_prior)
    return {k: logsumexp(v) for k, v in by.items()}


def workflow_log_prior(classes: list[str]) -> dict[str, float]:
    """ln prior of each class under the workflow's ``PRIOR_MASS``, renormalised over ``classes``."""
    cands = explanations()
    by_name = {c.name: log_prior(c, cands) for c in cands}
    raw = {k: by_name[k] for k in classes}
    norm = logsumexp(list(raw.values()))
    return {k: v - norm for k, v in raw.items()}


def with_prior(r: dict[str, Any], old: dict[str, float], new: dict[str, float]) -> dict[str, Any]:
    """A world's result decided again under another class prior."""
    post = {k: v - old[k] + new[k] for k, v in r["post"].items()}
    post = dict(sorted(post.items(), key=lambda kv: -kv[1]))
    return {**r, "post": post, "top": next(iter(post))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("file", type=Path, help="the oracle's --out JSON")
    results = json.loads(ap.parse_args(argv).file.read_text())
    judge = judge_log_prior()
    workflow = workflow_log_prior(list(judge))
    print("class priors (judge, workflow): " + ", ".join(
        f"{k} {np.exp(judge[k]):.3f}/{np.exp(workflow[k]):.3f}" for k in sorted(judge, key=lambda k: -judge[k])))
    for scale in sorted({r["scale"] for r in results}):
        rs = [r for r in results if r["scale"] == scale]
        moved = [with_prior(r, judge, workflow) for r in rs]
        right = sum(r["top"] == r["truth"] for r in rs), sum(r["top"] == r["truth"] for r in moved)
        print(f"noise {scale:g}, {len(rs)} worlds: top = truth {right[0]} with the judge's prior, "
              f"{right[1]} with the workflow's")
        print(reliability(rs).replace("oracle reliability", "judge's prior"))
        print(reliability(moved).replace("oracle reliability", "workflow's prior"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
