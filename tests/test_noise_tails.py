"""The point noise's tail weight, estimated from the repetitions and drawn by the lack-of-fit reference."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from labctl.discrepancy.data import build_dataset
from labctl.discrepancy.noise import estimate_noise
from labctl.discrepancy.synthetic import NoiseModel, synthesize
from labctl.discrepancy.tails import GAUSSIAN, LEAST_DOF, tail_dof, unit_draws
from labctl.physics import ContactLaw

DESIGN = build_dataset(synthesize(ContactLaw("tripp", 2e-3).stiffness_n_per_m, noise=NoiseModel(1e-12, 1e-12),
                                  seed=0))


def campaign(draw: np.ndarray, rng: np.random.Generator):
    """The 7-type design with point noise ``draw`` (unit variance, scaled to 1.2 %) and a 0.5 % seating offset."""
    runs = DESIGN.run_ids()
    return DESIGN.with_ln_stiffness(DESIGN.ln_stiffness + 0.012 * draw
                                    + 0.005 * rng.standard_normal(int(runs.max()) + 1)[runs])


def test_draws_have_unit_variance_and_the_tails_asked_for():
    rng = np.random.default_rng(3)
    t5 = unit_draws(rng, 5.0, 400_000)
    assert abs(np.var(t5) - 1.0) < 0.03
    assert np.mean(t5**4) > 3.0 * 1.8  # excess kurtosis of a t5 is 6
    gauss = unit_draws(np.random.default_rng(3), GAUSSIAN, 1000)
    assert np.array_equal(gauss, np.random.default_rng(3).standard_normal(1000))  # the Gaussian draws as before


def test_gaussian_repetitions_read_as_gaussian_and_heavy_tails_as_a_student_t():
    rng = np.random.default_rng(7)
    gaussian = [estimate_noise(campaign(rng.standard_normal(DESIGN.n_points), rng)).tail_dof for _ in range(30)]
    heavy = [estimate_noise(campaign(unit_draws(rng, 4.5, DESIGN.n_points), rng)).tail_dof for _ in range(30)]
    assert sum(math.isinf(v) for v in gaussian) >= 21  # the estimate's scatter passes its one-σ bar about 1 in 6
    assert sum(math.isfinite(v) for v in heavy) >= 18  # the gross-outlier screen takes the farthest draws
    assert np.median(heavy) < 10.0 and min(heavy) >= LEAST_DOF


def test_the_residuals_mixing_is_undone():
    # residuals of a cell mean of three keep half the excess kurtosis: f = 0.5 doubles it back
    rng = np.random.default_rng(11)
    x = unit_draws(rng, 6.0, (20_000, 3))  # excess kurtosis 3
    e = x - x.mean(axis=1, keepdims=True)
    z = (e / math.sqrt(2.0 / 3.0)).ravel()
    f = np.full(z.size, ((2 / 3) ** 4 + 2 * (1 / 3) ** 4) / (2 / 3) ** 2)
    assert abs(f[0] - 0.5) < 1e-12
    assert 5.0 < tail_dof(z, f) < 7.5


def test_heavy_tails_widen_the_lack_of_fit_reference():
    rng = np.random.default_rng(5)
    data = campaign(unit_draws(rng, 4.5, DESIGN.n_points), rng)
    floor = estimate_noise(data)
    assert math.isfinite(floor.tail_dof)
    gaussian = replace(floor, tail_dof=GAUSSIAN)
    heavy_ref, gauss_ref = floor.reference(data), gaussian.reference(data)
    f99 = 4.0
    assert heavy_ref.p(f99, 20) > gauss_ref.p(f99, 20)
