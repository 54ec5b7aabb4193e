"""Speed of the lack-of-fit test's simulated reference: its draws sharing the campaign's design, and not.

Every reference (``labctl.discrepancy.lof_reference``) estimates the noise anew on 100 simulated campaigns that
differ from the data only in ln k. What depends on the loads and seatings alone — the replicate sets, the two-way
fit's pseudo-inverse per case, each point's neighbour lines, the load bands and seating ends of the screen, the
points the seating σ is estimated from — is worked out once per design (``Dataset.design_memo``) and shared by the
draws. Here each campaign's reference is simulated twice in one run, the draws sharing the design and each draw
given a fresh one (everything recomputed, as before the memo), and the CPU times are printed side by side with
their ratio; the two references must agree (the same draws, the same arithmetic).

    python bench/lof_reference_speed.py [--seeds 2]

Run by hand (not a test); about a minute and a half.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from discrepancy_blind import blind_worlds, csv_points  # noqa: E402

from labctl.discrepancy.data import Dataset, build_dataset  # noqa: E402
from labctl.discrepancy.lof_reference import Reference, simulate  # noqa: E402
from labctl.discrepancy.noise import estimate_noise, null_statistic  # noqa: E402


def _fresh_design(campaign: Dataset) -> tuple[float, int] | None:
    """The null statistic on a campaign that shares nothing with the data it was drawn like."""
    return null_statistic(Dataset(campaign.cases))


def timed(data: Dataset, statistic: Callable[[Dataset], tuple[float, int] | None]) -> tuple[Reference | None, float]:
    """The reference for ``data`` with this null statistic, and its CPU time."""
    noise = estimate_noise(data)
    start = time.process_time()
    ref = simulate(data, noise.sigma_at(data), noise.seating_sigma, statistic)
    return ref, time.process_time() - start


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2, help="seeds per judge and scenario (noise 1×)")
    args = ap.parse_args()
    print("| judge | campaigns | reference, design shared [s] | design per draw [s] | ratio | references agree |")
    print("|---|---|---|---|---|---|")
    for judge_name in ("blind", "blind2"):
        judge = blind_worlds(judge_name)
        shared, fresh, agree, n = [], [], 0, 0
        for scenario in judge.SCENARIOS:
            for seed in range(200_000, 200_000 + args.seeds):
                data = build_dataset(csv_points(judge.generate(scenario, seed, 1.0).rows))
                ref_a, t_a = timed(data, null_statistic)
                ref_b, t_b = timed(data, _fresh_design)
                shared.append(t_a)
                fresh.append(t_b)
                n += 1
                agree += (ref_a is None and ref_b is None) or (
                    ref_a is not None and ref_b is not None and abs(ref_a.scale / ref_b.scale - 1) < 1e-6
                    and abs(ref_a.dfd / ref_b.dfd - 1) < 1e-6)
        a, b = statistics.mean(shared), statistics.mean(fresh)
        print(f"| {judge_name} | {n} | {a:.3f} | {b:.3f} | {b / a:.2f} | {agree}/{n} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
