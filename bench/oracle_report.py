"""What the oracle ceiling (``bench/oracle_ceiling.py``) prints: its top-1 per noise scale, read for the whole truth
and per effect, the misses, and how far a finer integral moves the ranking."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.special import logsumexp


def report(results: list[dict[str, Any]], scales: list[float], scenarios: Sequence[str]) -> None:
    """Top-1 accuracy per noise scale: library truths ≥ 3σ, all worlds, per scenario; the misses (confusions)."""
    for scale in scales:
        rs = [r for r in results if r["scale"] == scale]
        lib = [r for r in rs if r["truth"] not in ("none", "unlisted") and r["size"] >= 3.0]
        n_lib, n_all = sum(r["top"] == r["truth"] for r in lib), sum(r["top"] == r["truth"] for r in rs)
        n_seen = sum(r["top"] in (r["truth"], r["seen"]) for r in lib)  # a term under 3σ need not be named
        print(f"noise {scale:g}: library truths >= 3 sigma {n_lib}/{len(lib)} = {n_lib / max(len(lib), 1):.2f};"
              f"  its terms >= 3 sigma {n_seen}/{len(lib)} = {n_seen / max(len(lib), 1):.2f};"
              f"  all worlds {n_all}/{len(rs)} = {n_all / max(len(rs), 1):.2f}"
              f"  ({np.median([r['seconds'] for r in rs]):.1f} s per world, median)")
        cells = [f"{sc} {sum(r['top'] == r['truth'] for r in rs if r['scenario'] == sc)}/"
                 f"{sum(r['scenario'] == sc for r in rs)}" for sc in scenarios]
        print("\n".join("  " + ", ".join(cells[i:i + 4]) for i in range(0, len(cells), 4)))
        for r in (r for r in rs if r["top"] != r["truth"]):
            odds, rank = r["post"][r["top"]] - r["post"][r["truth"]], list(r["post"]).index(r["truth"]) + 1
            print(f"  miss {r['scenario']}/{r['seed']} ({r['size']:.1f} sigma): {r['truth']} -> {r['top']}  "
                  f"(truth rank {rank}, ln odds {odds:.1f})")


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
