"""The lack-of-fit test read against its null distribution simulated under the estimated noise model."""

from __future__ import annotations

import numpy as np

from labctl.discrepancy import run_discrepancy
from labctl.discrepancy.data import Dataset, build_dataset
from labctl.discrepancy.lof_reference import Reference
from labctl.discrepancy.noise import estimate_noise
from labctl.discrepancy.outliers import _neighbour_residuals, gross_outliers
from labctl.discrepancy.search import Search
from labctl.discrepancy.synthetic import NoiseModel, synthesize
from labctl.discrepancy.workflow import baseline_spec
from labctl.physics import ContactLaw, SurfaceRoughness

NULL_NOISE = NoiseModel(0.02, 0.02 / 3)


def campaign(*effects, seed=0):
    return synthesize(ContactLaw("tripp", 2e-3, effects).stiffness_n_per_m, noise=NULL_NOISE, seed=seed,
                      seating_rel=0.006)


def baseline_test(points, simulated=True):
    data = build_dataset(points)
    noise = estimate_noise(data)
    spec = baseline_spec("tripp")
    fit = Search(data, noise).fit(spec)
    return noise, data, noise.lack_of_fit(data, fit.residuals, fit.sigma, spec.n_params(), simulated=simulated)


def test_a_campaign_with_other_ln_k_keeps_its_design():
    data = build_dataset(campaign())
    y = np.arange(data.n_points, dtype=float)
    other = data.with_ln_stiffness(y)
    assert np.array_equal(other.ln_stiffness, y)
    assert np.array_equal(other.load_n, data.load_n) and np.array_equal(other.run_ids(), data.run_ids())


def test_campaigns_sharing_a_design_estimate_their_noise_as_if_each_were_new():
    # the draws share what the loads and seatings alone decide; a gross outlier in one draw changes which points
    # are kept, and its noise must then be that of the campaign without it, before and after a draw without one
    data = build_dataset(campaign())
    rng = np.random.default_rng(3)
    clean = 0.01 * rng.standard_normal(data.n_points) + 0.01 * rng.standard_normal(data.n_points)[data.run_ids()]
    i = data.n_points // 2
    bad = clean.copy()
    bad[i] += 0.3
    without = np.arange(data.n_points) == i
    for y in (clean, bad, clean, bad):
        shared = estimate_noise(data.with_ln_stiffness(y))
        alone = (estimate_noise(Dataset(data.with_ln_stiffness(y).cases)) if y is clean
                 else estimate_noise(data.with_ln_stiffness(y).drop_points(without)))
        assert shared.outliers == ((i,) if y is bad else ()) and alone.outliers == ()
        assert shared.seating_sigma > 0.005
        assert np.allclose((shared.sigma, shared.seating_sigma, *shared.band_sigma),
                           (alone.sigma, alone.seating_sigma, *alone.band_sigma), rtol=1e-9, atol=0)


def test_the_screens_lines_and_ends_follow_the_points_kept_on_a_shared_design():
    # with a seating's lowest point left out the next one ends it, and an end point is judged more leniently on its
    # lines (it is only extrapolated to): campaigns sharing the design must judge as campaigns of their own do
    data = build_dataset(campaign())
    keep = np.ones(data.n_points, dtype=bool)
    fewer = keep.copy()
    fewer[[0, data.n_points // 2]] = False  # a seating's lowest point and a point inside one
    groups = estimate_noise(data).groups
    across = np.random.default_rng(0).standard_normal(data.n_points)
    across[1] = 50.0  # point 1 far off its step's other repetitions
    for off in np.arange(0.1, 0.3, 0.02):  # point 1 off its seating's lines by 1-5 robust σ
        y = data.ln_stiffness.copy()
        y[1] += off
        for mask in (keep, fewer):
            shared = data.with_ln_stiffness(y)
            fresh = Dataset(shared.cases)
            for got, want in zip(_neighbour_residuals(shared, mask), _neighbour_residuals(fresh, mask), strict=True):
                assert np.array_equal(got, want, equal_nan=True)
            a = np.where(mask, across, np.nan)
            assert gross_outliers(shared, mask, groups, 12, 4, a) == gross_outliers(fresh, mask, groups, 12, 4, a)


def test_the_reference_is_a_scaled_f_and_the_same_every_time():
    noise, data, test = baseline_test(campaign(seed=1))
    ref = noise.reference(data)
    assert isinstance(ref, Reference) and 0.8 < ref.scale < 1.3 and ref.dfd > 20
    assert test.p == baseline_test(campaign(seed=1))[2].p  # fixed draws
    assert 0.0 <= test.p <= 1.0 and ref.p(2.0 * test.f + 1.0, test.df_lack) < test.p


def test_a_null_campaign_the_plain_f_test_rejects_is_consistent_with_the_noise():
    # the plain F reference ignores that σ(F) and σ_seat were estimated from the same repetitions; on this null
    # campaign it rejected the exact baseline at 0.01 and the workflow said "unexplained"
    points = campaign(seed=166)
    assert baseline_test(points, simulated=False)[2].p < 0.01
    assert baseline_test(points)[2].p >= 0.01
    assert run_discrepancy(points).verdict == "consistent"


def test_an_effect_is_still_found_against_the_simulated_reference():
    _, _, test = baseline_test(campaign(SurfaceRoughness(asperity_scale=0.5), seed=2))
    assert test.p < 1e-4
