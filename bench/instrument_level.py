"""Does the measurement-side instrument check hold its level? An exact load offset, many seeds, each noise input
known or estimated.

    python bench/instrument_level.py [--seeds 60]

The project's own generator (``labctl.discrepancy.synthetic``): Tripp at 2 mm plus a load cell reading 15 N high,
point noise 1.5 % at each roller type's preload falling to 0.5 % at its top load, a seating offset per repetition.
The load-offset model is fitted, and its per-roller-type levels are compared in the check's linearised form (the
offset's direction d ln k/dθ, one level per roller geometry, χ² on G − 1 df against the whitened residuals) with
the point σ and the seating σ either the generator's own or estimated as the workflow does
(``estimate_noise``). A level test rejects a true offset in 1 % of seeds at level 0.01 and 10 % at 0.1.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.special import chdtrc

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from labctl.discrepancy import build_dataset  # noqa: E402
from labctl.discrepancy.data import Dataset  # noqa: E402
from labctl.discrepancy.model import ModelSpec, fit_model, residuals_at  # noqa: E402
from labctl.discrepancy.noise import estimate_noise, whiten  # noqa: E402
from labctl.discrepancy.synthetic import NoiseModel, protocol_loads, synthesize  # noqa: E402
from labctl.physics import ContactLaw  # noqa: E402

NOISE = NoiseModel(0.015, 0.005)
OFFSET_N = 15.0
SEATING = 0.0015


def truth(case, load_n):  # noqa: ANN001, ANN201
    """Tripp at 2 mm, measured with a load cell that reads ``OFFSET_N`` high."""
    return ContactLaw("tripp", 2e-3).stiffness_n_per_m(case, load_n - OFFSET_N)


def true_sigma(data: Dataset) -> np.ndarray:
    return np.concatenate([NOISE.sigma(c.load_n, protocol_loads(c.case)[-1]) for c in data.cases])


def level_q(data: Dataset, sigma: np.ndarray, seating: float) -> float:
    """The per-roller-type levels' χ² of the fitted load offset (the check's linearised form)."""
    fit = fit_model(data, ModelSpec().with_effects("load_offset"), sigma=sigma, seating_sigma=seating)
    runs = data.run_ids()
    z = whiten(runs, fit.residuals, sigma, seating)
    geometry = data.roller_index()
    x = fit.x.copy()
    x[1] += 1e-6
    d = (residuals_at(data, fit.spec, x, data.ln_stiffness) - fit.residuals) / 1e-6

    def rss(columns: list[np.ndarray]) -> float:
        a = whiten(runs, np.column_stack(columns), sigma, seating)
        coef, *_ = np.linalg.lstsq(a, z, rcond=None)
        e = z - a @ coef
        return float(e @ e)

    return rss([d]) - rss([d * (geometry == g) for g in range(geometry.max() + 1)])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=60)
    args = parser.parse_args()
    rows = []
    for seating, point, seat_from in ((0.0, "generator's", "generator's"), (0.0, "estimated", "estimated"),
                                      (SEATING, "generator's", "generator's"), (SEATING, "generator's", "estimated"),
                                      (SEATING, "estimated", "generator's"), (SEATING, "estimated", "estimated")):
        qs, ratio = [], []
        for seed in range(700, 700 + args.seeds):
            data = build_dataset(synthesize(truth, noise=NOISE, seed=seed, seating_rel=seating))
            floor = estimate_noise(data)
            sigma = true_sigma(data) if point == "generator's" else floor.sigma_at(data)
            qs.append(level_q(data, sigma, seating if seat_from == "generator's" else floor.seating_sigma))
            ratio.append(floor.sigma_at(data)[:11] / true_sigma(data)[:11])
        q = np.array(qs)
        p = chdtrc(6, q)
        rows.append(f"| {seating:g} | {point} | {seat_from} | {q.mean():.2f} | {np.sum(p < 0.01)}/{q.size} | "
                    f"{np.sum(p < 0.1)}/{q.size} |")
    print(f"exact {OFFSET_N:g} N load offset, seeds 700-{699 + args.seeds}; a level test: 6 mean, 1 % and 10 %\n")
    print("| seating σ | point σ | seating σ used | mean Q (6 df) | p < 0.01 | p < 0.1 |\n|---|---|---|---|---|---|")
    print("\n".join(rows))
    r = np.mean(ratio, axis=0)
    print(f"\nestimated / generator's point σ, roller type 1, lowest to highest step: "
          f"{' '.join(f'{v:.2f}' for v in r)}")


if __name__ == "__main__":
    main()
