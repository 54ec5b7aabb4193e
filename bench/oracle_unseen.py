"""The oracle ceiling when the truth's law is not among the laws it knows: how high can any method rank an effect
whose functional form it has never seen?

``bench/oracle_ceiling.py`` knows every law the blind judge writes, the outside effects' included, so its top-1 is a
ceiling for a method that holds the true law of every effect. The acceptance asks for effects in *forms unlike the
library's*. This bench asks the oracle the same question with the world's own law taken away: every sub-hypothesis
that uses a family of the world's truth (a library effect's family, or the outside effect's) is dropped, and each
class keeps its prior mass, spread over the laws that are left (the other two or three families of the same effect;
for an outside effect, the other three outside laws stand for "an effect outside the library"). That is a method
which knows every law of the judge except the one at work, laws more like the truth's than a library written without
the judge. It is not a strict ceiling: exact evidence on a sibling law has no room for the form's doubt, and a method
with a discrepancy term or a law nearer the truth's can do better. It measures how much the oracle's top-1 and its
reliability stand on holding the world's own law.

Each world's sub-hypothesis evidences are computed once, in the oracle's own order (so the known-law posterior is the
oracle's, bit for bit), and both posteriors are printed: top-1 with 95 % Wilson intervals for the library truths
≥ 3σ (whole truth, and per effect ≥ 3σ as the oracle reads it) and over all worlds, and each one's reliability.

    python bench/oracle_unseen.py --seeds 10 --noise 1 --workers 2 [--out F]
"""

from __future__ import annotations

import argparse
import json
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
from oracle_ceiling import W, World, evidence, hypotheses, logsumexp
from oracle_report import count_share, library_big, reliability, truth_classes


def sub_evidence(rows: list[dict[str, Any]], noise: dict[str, float]) -> list[tuple[str, list[str], float, float]]:
    """Every sub-hypothesis as (class label, its family names, ln prior, ln evidence), in the oracle's order."""
    world = World(rows, noise)
    return [(h.label, [p.fam.name for p in h.parts if p.fam is not None], float(h.log_prior),
             float(evidence(world, h))) for h in hypotheses()]


def posterior(subs: list[tuple[str, list[str], float, float]], unseen: frozenset[str] = frozenset()
              ) -> dict[str, float]:
    """ln posterior (unnormalised) of every class, best first, with the ``unseen`` families' sub-hypotheses dropped
    and each class's prior mass kept (spread over what is left); a class with no law left gets none."""
    prior: dict[str, list[float]] = {}
    kept: dict[str, list[tuple[float, float]]] = {}
    for name, fams, lp, ev in subs:
        prior.setdefault(name, []).append(lp)
        if not unseen.intersection(fams):
            kept.setdefault(name, []).append((lp, ev))
    post = {k: logsumexp(prior[k]) - logsumexp([lp for lp, _ in v]) + logsumexp([lp + ev for lp, ev in v])
            for k, v in kept.items()}
    return dict(sorted(post.items(), key=lambda kv: -kv[1]))


def decided(r: dict[str, Any]) -> dict[str, Any]:
    """A world's result with both posteriors and their tops worked out from its sub-hypotheses."""
    subs = [tuple(s) for s in r["subs"]]
    known, blind = posterior(subs), posterior(subs, frozenset(r["unseen_families"]))
    return {**r, "post": known, "top": next(iter(known)), "post_unseen": blind, "top_unseen": next(iter(blind))}


def run_world(task: tuple[str, int, float]) -> dict[str, Any]:
    """Generate one world; its class posterior with every law known and with its own law unseen."""
    (scenario, seed, scale), t0 = task, time.perf_counter()
    ds = W.generate(scenario, seed, scale)
    truth, seen = truth_classes(ds.truth)
    return decided({"scenario": scenario, "seed": seed, "scale": scale, "truth": truth, "seen": seen,
                    "size": float(ds.truth["size_sigma"]), "unseen_families": sorted(set(ds.truth["family"].values())),
                    "subs": sub_evidence(ds.rows, ds.truth["noise"]), "seconds": time.perf_counter() - t0})


def summary(rs: list[dict[str, Any]], which: str) -> str:
    """Top-1 of one posterior: library truths ≥ 3σ (whole, per effect), all worlds."""
    top = "top" if which == "known" else "top_unseen"
    lib = [r for r in rs if library_big(r)]
    whole, per = sum(r[top] == r["truth"] for r in lib), sum(r[top] in (r["truth"], r["seen"]) for r in lib)
    every = sum(r[top] == r["truth"] for r in rs)
    outside = [r for r in rs if r["truth"] == "unlisted"]
    return (f"  law {which:6s}: library truths >= 3 sigma {count_share(whole, len(lib))}; per effect "
            f"{count_share(per, len(lib))}; all worlds {count_share(every, len(rs))}; "
            f"outside effects ranked unlisted {sum(r[top] == 'unlisted' for r in outside)}/{len(outside)}")


def as_unseen(r: dict[str, Any]) -> dict[str, Any]:
    """A world's result read with its own law unseen (for the reliability line)."""
    return {**r, "post": r["post_unseen"], "top": r["top_unseen"]}


def report(results: list[dict[str, Any]]) -> None:
    """Per noise scale: both posteriors' top-1 and reliability, and where the unseen law moves the top."""
    for scale in sorted({r["scale"] for r in results}):
        rs = [r for r in results if r["scale"] == scale]
        print(f"noise {scale:g}, {len(rs)} worlds:")
        print(summary(rs, "known"))
        print(summary(rs, "unseen"))
        print(reliability(rs).replace("oracle reliability", "law known "))
        print(reliability([as_unseen(r) for r in rs]).replace("oracle reliability", "law unseen"))
        moved = Counter(f"{r['truth']} ({'/'.join(r['unseen_families'])}) -> {r['top_unseen']}"
                        for r in rs if r["top"] == r["truth"] != r["top_unseen"])
        for key, n in moved.most_common():
            print(f"    right with the law known, not unseen: {key} x{n}")


def main(argv: list[str] | None = None) -> int:
    """Run the oracle with the truth's law known and unseen over the judge's scenarios x seeds x noise scales."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3, help="evaluation seeds 0..N-1 per scenario")
    ap.add_argument("--noise", default="1", help="noise scales, comma-separated")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, help="also write every world's result (sub-hypotheses included) as JSON")
    ap.add_argument("--rescore", type=Path, help="report a stored --out file instead of running")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    if args.rescore:
        results = [decided(r) for r in json.loads(args.rescore.read_text())]
    else:
        tasks = [(sc, s, float(x)) for x in args.noise.split(",") for sc in W.SCENARIOS for s in range(args.seeds)]
        with ProcessPoolExecutor(args.workers) as pool:
            results = list(pool.map(run_world, tasks, chunksize=1))
        if args.out:
            args.out.write_text(json.dumps(results))
    report(results)
    print(f"{len(results)} worlds in {time.perf_counter() - t0:.0f} s"
          f" ({np.median([r['seconds'] for r in results]):.1f} s per world, median)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
