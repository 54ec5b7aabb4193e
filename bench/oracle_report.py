"""What the oracle ceiling (``bench/oracle_ceiling.py``) prints: its top-1 per noise scale with 95 % Wilson intervals,
read for the whole truth and per effect, the misses, its own stated probabilities against its share right, and how far
a finer integral moves the ranking; and how a world's truth is labelled, as the discrepancy bench labels it."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from intervals import RELIABILITY_BINS, wilson
from scipy.special import logsumexp

from labctl.physics import EFFECTS  # the effects' order only, to label truths as the bench does

BINS = (*RELIABILITY_BINS[:4], (RELIABILITY_BINS[4][0], RELIABILITY_BINS[5][1]))
"""Stated-probability bins of the oracle's reliability lines: the evaluation's, its top two merged (fewer worlds)."""


def label(effects: list[str], calibration: list[str]) -> str:
    """A class as ``truth_name`` (bench/discrepancy_blind.py, which imports the workflow) names a library truth."""
    return " + ".join([n for n in EFFECTS if n in effects] + list(calibration)) or "none"


def truth_classes(truth: dict[str, Any]) -> tuple[str, str]:
    """A world's truth class, and the class of its terms of size ≥ 3σ (what the per-effect reading counts)."""
    name = "unlisted" if truth["outside_library"] else label(truth["effects"], truth["measurement_effects"])
    by = truth.get("size_sigma_by_effect") or {}
    seen = [[n for n in truth[k] if by.get(n, 0.0) >= 3.0] for k in ("effects", "measurement_effects")]
    return name, label(*seen) if any(seen) and name != "unlisted" else name


def library_big(r: dict[str, Any]) -> bool:
    """A world whose truth is a library explanation (not none, not unlisted) of size ≥ 3σ."""
    return r["truth"] not in ("none", "unlisted") and r["size"] >= 3.0


def report(results: list[dict[str, Any]], scales: list[float], scenarios: Sequence[str], out: Path | None = None
           ) -> None:
    """Top-1 accuracy per noise scale: library truths ≥ 3σ, all worlds, per scenario; the misses (confusions), the
    oracle's reliability; with ``out``, every world's result (its posterior included) written there as JSON."""
    if out:
        out.write_text(json.dumps(results))
    for scale in scales:
        rs = [r for r in results if r["scale"] == scale]
        lib = [r for r in rs if library_big(r)]
        n_lib, n_all = sum(r["top"] == r["truth"] for r in lib), sum(r["top"] == r["truth"] for r in rs)
        n_seen = sum(r["top"] in (r["truth"], r["seen"]) for r in lib)  # a term under 3σ need not be named
        print(f"noise {scale:g}: library truths >= 3 sigma {count_share(n_lib, len(lib))};"
              f"  its terms >= 3 sigma {count_share(n_seen, len(lib))};"
              f"  all worlds {n_all}/{len(rs)} = {n_all / max(len(rs), 1):.2f}"
              f"  ({np.median([r['seconds'] for r in rs]):.1f} s per world, median)")
        cells = [f"{sc} {sum(r['top'] == r['truth'] for r in rs if r['scenario'] == sc)}/"
                 f"{sum(r['scenario'] == sc for r in rs)}" for sc in scenarios]
        print("\n".join("  " + ", ".join(cells[i:i + 4]) for i in range(0, len(cells), 4)))
        for r in (r for r in rs if r["top"] != r["truth"]):
            odds, rank = r["post"][r["top"]] - r["post"][r["truth"]], list(r["post"]).index(r["truth"]) + 1
            print(f"  miss {r['scenario']}/{r['seed']} ({r['size']:.1f} sigma): {r['truth']} -> {r['top']}  "
                  f"(truth rank {rank}, ln odds {odds:.1f})")
        print(reliability(rs))


def share(k: int, n: int) -> str:
    """A share with its 95 % Wilson interval."""
    if n == 0:
        return "-"
    p, lo, hi = wilson(k, n)
    return f"{p:.2f} ({lo:.2f}-{hi:.2f})"


def count_share(k: int, n: int) -> str:
    """k/n = the share with its 95 % Wilson interval."""
    return f"{k}/{n} = {share(k, n)}"


def stated(r: dict[str, Any]) -> float:
    """The oracle's own probability of its top class: its posterior over the truth classes, normalised."""
    post = np.array(list(r["post"].values()))
    return float(np.exp(post.max() - logsumexp(post)))


def reliability(rs: list[dict[str, Any]]) -> str:
    """The oracle's stated probability of its top class against how often that class is the truth, per bin: with
    the judge's own families and priors a forecaster can be reliable; this says how near the oracle's integral is."""
    p, right = np.array([stated(r) for r in rs]), np.array([r["top"] == r["truth"] for r in rs])
    cells = []
    for lo, hi in BINS:
        inside = (p >= lo) & (p < hi)
        if inside.any():
            cells.append(f"{lo:g}-{min(hi, 1):g}: stated {p[inside].mean():.2f}, right "
                         f"{share(int(right[inside].sum()), int(inside.sum()))} of {int(inside.sum())}")
    return "  oracle reliability: " + "; ".join(cells)


def validate(std: list[dict[str, Any]], fine: list[dict[str, Any]]) -> None:
    """How much the class ranking moves when the integral is done finer."""
    print("validation (standard vs finer: 3x screen, 4 starts, 300-draw importance sample), ln P normalised:")
    for a, b in zip(std, fine, strict=True):
        na, nb, top5 = logsumexp(list(a["post"].values())), logsumexp(list(b["post"].values())), list(a["post"])[:5]
        print(f"  {a['scenario']}/{a['seed']} (truth {a['truth']}): top {a['top']} -> {b['top']}; truth rank "
              f"{list(a['post']).index(a['truth']) + 1} -> {list(b['post']).index(b['truth']) + 1}, ln P "
              f"{a['post'][a['truth']] - na:.2f} -> {b['post'][b['truth']] - nb:.2f}; standard top 5 at fine ranks "
              f"{[list(b['post']).index(k) + 1 for k in top5]}, max |d ln P| "
              f"{max(abs(a['post'][k] - na - b['post'][k] + nb) for k in top5):.2f}")
    print(f"  top-1 unchanged in {sum(a['top'] == b['top'] for a, b in zip(std, fine, strict=True))}/{len(std)} worlds")
