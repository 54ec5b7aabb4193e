"""The decision procedure: candidate explanations with posterior probabilities, the form discrepancy integrated
out exactly, outliers judged against the local repetition spread, ball runs refused."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import logsumexp

from labctl.discrepancy import load_points, run_discrepancy
from labctl.discrepancy.form import TAU_GRID, FormPrior
from labctl.discrepancy.model import FIT_ONLY_BOUNDS, ModelSpec
from labctl.discrepancy.occam import HYPER_A, log_bayes_factor
from labctl.discrepancy.posterior import PRIOR_MASS, explanations, log_prior
from labctl.discrepancy.report import summary_text
from labctl.discrepancy.synthetic import NoiseModel, synthesize
from labctl.errors import InputError
from labctl.physics import ContactLaw, EndEffects, Misalignment, SurfaceRoughness
from labctl.stiffness_table import write_stiffness_table
from tests.discrepancy_util import GENERATOR_NOISE, world


def test_form_discrepancy_marginal_is_the_dense_gaussian_integral():
    rng = np.random.default_rng(4)
    a = rng.normal(size=(40, 6))
    e = rng.normal(size=40) + a @ rng.normal(scale=0.05, size=6)
    u, s, _ = np.linalg.svd(a, full_matrices=False)
    form = FormPrior(u, s**2)
    dense = []
    for tau in TAU_GRID:
        cov = np.eye(40) + tau**2 * a @ a.T
        dense.append(-0.5 * e @ np.linalg.solve(cov, e) - 0.5 * np.linalg.slogdet(cov)[1])
    expected = logsumexp(dense) - math.log(len(TAU_GRID))
    assert form.log_marginal(e)[0] == pytest.approx(expected, rel=1e-10, abs=1e-8)
    # The transform is Σ^(-1/2): its squared norm is the quadratic form at that τ.
    tau = TAU_GRID[7]
    t = form.transform(tau)(e)
    assert t @ t == pytest.approx(e @ np.linalg.solve(np.eye(40) + tau**2 * a @ a.T, e), rel=1e-10)


@pytest.mark.parametrize(("k", "scale"), [(1, 0.0), (1, 0.3), (2, 1.0), (3, 6.0)])
def test_the_occam_factor_is_the_hyper_g_integral_of_the_dense_gaussian_marginal(k, scale):
    # y ~ N(Xβ, I), β | g ~ N(0, g·(X'X)⁻¹), g ~ (a − 2)/2·(1 + g)^(−a/2): the Bayes factor against β = 0,
    # integrated over g by quadrature of the dense Gaussian densities, is the closed form at the fit's gain.
    rng = np.random.default_rng(k)
    x = rng.normal(size=(30, k))
    y = rng.normal(size=30) + scale * x @ np.ones(k)
    hat = x @ np.linalg.solve(x.T @ x, x.T)
    gain = float(y @ hat @ y)

    def log_ratio(g: float) -> float:
        cov = np.eye(30) + g * hat
        return -0.5 * (y @ np.linalg.solve(cov, y) - y @ y) - 0.5 * np.linalg.slogdet(cov)[1]
    peak = max(log_ratio(g) for g in np.logspace(-3, 5, 60))
    dense, _ = quad(lambda g: (HYPER_A - 2) / 2 * (1 + g) ** (-HYPER_A / 2) * math.exp(log_ratio(g) - peak),
                    0, np.inf, limit=400)
    assert log_bayes_factor(gain, k) == pytest.approx(math.log(dense) + peak, abs=1e-6)


@pytest.mark.parametrize("gain", [-400.0, -3.0, 0.0, 99.0, 101.0, 4000.0])
def test_the_occam_factor_is_continuous_and_charges_a_gain_within_the_noise_little(gain):
    # the closed form's two branches (series, incomplete gamma) agree across the switch and with the integral over
    # s = g/(1 + g); at no gain two parameters cost ln((a + k − 2)/(a − 2)) = ln 3, not BIC's ln n.
    def integrand(s: float) -> float:
        return (1 - s) ** ((HYPER_A + 2) / 2 - 2) * math.exp(s * gain / 2 - max(gain / 2, 0.0))
    direct = math.log((HYPER_A - 2) / 2 * quad(integrand, 0, 1, limit=400, points=[0.99, 0.9999])[0])
    assert log_bayes_factor(gain, 2) == pytest.approx(direct + max(gain / 2, 0.0), rel=1e-6, abs=1e-6)
    assert log_bayes_factor(0.0, 2) == pytest.approx(-math.log(3.0))


def test_the_prior_is_a_distribution_split_evenly_within_each_class():
    cands = explanations()
    assert len(cands) == 1 + 5 + 10 + 3 + 15 + 1
    total = sum(math.exp(log_prior(c, cands)) for c in cands)
    assert total == pytest.approx(1.0)
    assert sum(PRIOR_MASS.values()) == pytest.approx(1.0)
    singles = {math.exp(log_prior(c, cands)) for c in cands if c.kind == "physical"}
    assert len(singles) == 1 and singles.pop() == pytest.approx(PRIOR_MASS["physical"] / 5)


@pytest.fixture(scope="module")
def null_points():
    return synthesize(world(), noise=GENERATOR_NOISE, seating_rel=0.004, seed=11)


def _with_two_outliers(points, factor, roller_type=3, step=5):
    """Two of the three repetitions of one roller type at one load step off by the same factor."""
    steps = sorted({p.load_n for p in points if p.roller_type == roller_type and p.repetition == 1})
    out, bad = [], []
    for p in points:
        if p.roller_type == roller_type and p.repetition in (1, 2):
            own = sorted(q.load_n for q in points if q.roller_type == roller_type and q.repetition == p.repetition)
            if p.load_n == own[step]:
                p = dataclasses.replace(p, stiffness_n_per_m=p.stiffness_n_per_m * factor)
                bad.append((p.repetition, p.load_n))
        out.append(p)
    assert len(bad) == 2 and len(steps) == 11
    return out, bad


@pytest.mark.parametrize("factor", [1.12, 0.9])
def test_two_outliers_in_one_step_are_set_aside_and_the_clean_repetition_kept(null_points, factor):
    points, bad = _with_two_outliers(null_points, factor)
    result = run_discrepancy(points)
    found = sorted((o["repetition"], o["load_n"]) for o in result.screening.outliers)
    assert found == sorted(bad)
    assert result.verdict == "consistent" and not result.steps
    assert result.verdict == run_discrepancy(null_points).verdict


@pytest.mark.parametrize(("roller_type", "factor"), [(1, 1.12), (5, 1.12), (3, 1.12), (3, 0.88), (5, 0.88)])
def test_two_outliers_that_outvote_the_clean_repetition_at_a_lowest_step_are_set_aside(null_points, roller_type,
                                                                                        factor):
    # 12 % off in two of three repetitions where the point noise is 2 %: their lines only extrapolate to them and
    # they outvote the clean one, so the point screen keeps them. Before the step test the baseline failed the
    # lack-of-fit test on them alone on types 1 and 5 (the verdict was "unexplained"); where it passed, they stayed
    # in unreported until the step's mean was tested whatever the lack of fit.
    points, bad = _with_two_outliers(null_points, factor, roller_type, step=0)
    result = run_discrepancy(points)
    assert sorted((o["repetition"], o["load_n"]) for o in result.screening.outliers) == sorted(bad)
    assert result.verdict == "consistent"


@pytest.mark.parametrize(("roller_type", "step"), [(1, 0), (3, 2), (5, 0), (7, 0)])
def test_two_outliers_in_opposite_directions_are_set_aside_by_their_steps_spread(null_points, roller_type, step):
    # 8 % off each way in two of three repetitions: the step's mean stays, so the mean-shift test cannot see them,
    # and their lines (at low loads, 2 % noise) do not set them aside; before the spread test both were kept.
    points, bad = _with_two_outliers(null_points, 1.0, roller_type, step)
    points = [dataclasses.replace(p, stiffness_n_per_m=p.stiffness_n_per_m * (0.92 if p.repetition == 1 else 1.08))
              if (p.repetition, p.load_n) in bad and p.roller_type == roller_type else p for p in points]
    result = run_discrepancy(points)
    assert sorted((o["repetition"], o["load_n"]) for o in result.screening.outliers) == sorted(bad)
    assert result.verdict == "consistent"


def test_two_outliers_at_a_lowest_step_are_judged_against_the_most_probable_explanation():
    # with an end effect the baseline fails the lack-of-fit test everywhere, so only the explanation it is most
    # likely to be shows the one step out of line; before, the two points stayed in every fit, unreported.
    clean = synthesize(world(EndEffects(0.3e-3)), noise=GENERATOR_NOISE, seating_rel=0.004, seed=11)
    points, bad = _with_two_outliers(clean, 1.12, roller_type=1, step=0)
    result, without = run_discrepancy(points), run_discrepancy(clean)
    assert sorted((o["repetition"], o["load_n"]) for o in result.screening.outliers) == sorted(bad)
    assert (result.verdict, result.scored[0].explanation) == (without.verdict, without.scored[0].explanation)


@pytest.mark.parametrize("seed", range(6))
def test_one_roller_types_lowest_step_is_judged_against_its_own_noise_not_the_pooled_one(seed):
    # one roller type (33 points) with noise 2 % at the preload and a third of it at the top: a lowest point 4 %
    # off (2 σ there) is no gross outlier. Judged against one robust σ for every load, as before, 9 of these 12
    # were set aside, in the way the clean demo lost a point 1.1 % off where its preload spread is 2.2 %.
    law = ContactLaw("tripp", 2e-3).stiffness_n_per_m
    points = synthesize(law, types=[1], noise=GENERATOR_NOISE, seating_rel=0.004, seed=seed)
    low = min(p.load_n for p in points if p.repetition == 2)
    for factor in (1.04, 0.96):
        bumped = [dataclasses.replace(p, stiffness_n_per_m=p.stiffness_n_per_m * factor)
                  if p.repetition == 2 and p.load_n == low else p for p in points]
        assert run_discrepancy(bumped).screening.outliers == []


def test_without_repetitions_the_step_tests_are_not_made(null_points):
    # one seating per roller and no repetition numbers: the noise comes from neighbour differences and there is no
    # pure error to judge a step's mean or spread by (a campaign with no pure error at all made them divide by 0).
    single = [dataclasses.replace(p, repetition=None) for p in null_points if p.repetition == 1]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = run_discrepancy(single)
    assert result.noise.method == "neighbour-differences" and result.screening.outliers == []


def test_a_step_every_repetition_leaves_the_same_way_is_not_set_aside(null_points):
    # the lowest step of type 1 off by 12 %, 11 % and 9 %: the repetitions agree, so it is the contact's, not two
    # bad points outvoting a clean one.
    own = {r: min(p.load_n for p in null_points if p.roller_type == 1 and p.repetition == r) for r in (1, 2, 3)}
    factor = {1: 1.12, 2: 1.11, 3: 1.09}
    points = [dataclasses.replace(p, stiffness_n_per_m=p.stiffness_n_per_m * factor[p.repetition])
              if p.roller_type == 1 and p.load_n == own.get(p.repetition) else p for p in null_points]
    result = run_discrepancy(points)
    assert result.screening.outliers == [] and result.verdict != "consistent"


@pytest.mark.parametrize(("roller_type", "factor"), [(3, 0.88), (3, 1.12), (1, 0.88), (7, 0.88)])
def test_a_gross_outlier_at_a_seatings_lowest_step_is_set_aside(null_points, roller_type, factor):
    # 12 % off where the point noise is 2 %: its lines only extrapolate to it (with √6 times the noise), so before
    # it was judged against its step's other repetitions too it was kept.
    own = sorted(p.load_n for p in null_points if p.roller_type == roller_type and p.repetition == 2)
    points = [dataclasses.replace(p, stiffness_n_per_m=p.stiffness_n_per_m * factor)
              if p.roller_type == roller_type and p.repetition == 2 and p.load_n == own[0] else p for p in null_points]
    result = run_discrepancy(points)
    assert [(o["repetition"], o["load_n"]) for o in result.screening.outliers] == [(2, own[0])]
    assert result.verdict == "consistent"


def test_a_clean_point_after_a_gap_in_the_loads_is_not_taken_for_an_outlier():
    # a roughness twice the generator's, and the 2nd-4th load steps of every seating left out: the lines through
    # a point's neighbours miss the curve across the gap by many σ, but the point agrees with its step's other
    # repetitions; the screen set aside a clean point of type 3 (repetition 1, 377 N) until it asked them too
    points = synthesize(world(SurfaceRoughness(2.0)), noise=NoiseModel(0.01, 0.004), seating_rel=0.003, seed=1)
    rank = {(p.roller_type, p.repetition): sorted(q.load_n for q in points if (q.roller_type, q.repetition) ==
                                                  (p.roller_type, p.repetition)) for p in points}
    uneven = [p for p in points if rank[(p.roller_type, p.repetition)].index(p.load_n) not in (1, 2, 3)]
    assert run_discrepancy(uneven).screening.outliers == []


def _shared_step(points, roller_type, rank, factor):
    """Every repetition of one roller type at its load step of ``rank`` (0 the lowest, -1 the highest) off by
    ``factor`` (or by ``factor[repetition]``); the points moved, as (repetition, load)."""
    own = {r: sorted(p.load_n for p in points if p.roller_type == roller_type and p.repetition == r)
           for r in {p.repetition for p in points}}
    hit = [p.roller_type == roller_type and p.load_n == own[p.repetition][rank] for p in points]
    by = factor if isinstance(factor, dict) else dict.fromkeys(own, factor)
    moved = [dataclasses.replace(p, stiffness_n_per_m=p.stiffness_n_per_m * by[p.repetition]) if h else p
             for p, h in zip(points, hit, strict=True)]
    return moved, sorted((p.repetition, p.load_n) for p, h in zip(points, hit, strict=True) if h)


@pytest.mark.parametrize("factor", [1.1, 0.9])
def test_an_inner_step_every_repetition_leaves_the_same_way_is_the_steps_fault(null_points, factor):
    # one step inside type 3's load range 10 % off in all three seatings, the steps below and above it in line:
    # no smooth contact law does that (a load set or read wrong does); it was kept as the contact's shape and made
    # null data "NOT consistent"
    points, bad = _shared_step(null_points, 3, 5, factor)
    result = run_discrepancy(points)
    assert sorted((o["repetition"], o["load_n"]) for o in result.screening.outliers) == bad
    assert result.verdict == "consistent"


@pytest.mark.parametrize(("rank", "factor"), [(4, 1.1), (7, 0.9)])
def test_two_seatings_whose_two_points_of_one_step_are_off_stay_consistent(null_points, rank, factor):
    # a campaign of two seatings: two bad points of one step are every repetition it has, and no clean one is left
    # to keep (the third blind judge's null worlds with outliers were "unexplained" so)
    points, bad = _shared_step([p for p in null_points if p.repetition in (1, 2)], 5, rank, factor)
    result = run_discrepancy(points)
    assert sorted((o["repetition"], o["load_n"]) for o in result.screening.outliers) == bad
    assert result.verdict == "consistent"


def test_two_seatings_whose_two_points_of_one_step_leave_opposite_ways_are_both_reported(null_points):
    # the step's mean stays and its spread swells the pure error: "consistent", but with a noise floor the two
    # points set and neither reported; there is no clean repetition to keep
    points, bad = _shared_step([p for p in null_points if p.repetition in (1, 2)], 5, 6, {1: 1.1, 2: 0.9})
    result = run_discrepancy(points)
    assert sorted((o["repetition"], o["load_n"]) for o in result.screening.outliers) == bad
    assert result.verdict == "consistent"


def test_a_seatings_last_step_every_repetition_leaves_the_same_way_is_not_set_aside(null_points):
    # the highest step of type 5 off by 10 % in every seating: where a yield sets in, it may be the contact's, and the
    # data cannot tell; the verdict says that one step alone departs, and what to do
    points, bad = _shared_step(null_points, 5, -1, 0.9)
    result = run_discrepancy(points)
    assert result.screening.outliers == [] and result.verdict != "consistent"
    [note] = result.to_dict()["input_checks"]["end_steps"]
    assert note["step"] == "last" and note["load_n"] == sorted(load for _, load in bad)
    assert note["off_rel"] == pytest.approx(-0.1, abs=0.03)
    assert "the last step of type 5" in result.verdict_text() and "re-measure that step" in result.verdict_text()
    assert "input: 1 first or last step(s) off in every seating, kept" in summary_text(result.to_dict())
    assert run_discrepancy(null_points).to_dict()["input_checks"]["end_steps"] == []


def test_every_candidate_has_a_probability_and_a_name_needs_nine_tenths(null_points):
    doc = run_discrepancy(synthesize(world(EndEffects(0.1e-3)), noise=NoiseModel(0.01, 0.004), seating_rel=0.002,
                                     seed=3)).to_dict()
    probs = [c["probability"] for c in doc["explanations"]]
    assert sum(probs) == pytest.approx(1.0) and probs == sorted(probs, reverse=True)
    assert doc["decision"]["top"]["explanation"] == doc["explanations"][0]["explanation"]
    for step in doc["effects"] + doc["measurement_effects"]:
        assert step["evidence"]["probability"] >= 0.9
    if doc["verdict"] in ("likely", "unexplained"):
        assert doc["explanations"][0]["explanation"] in doc["verdict_text"]
    # a verdict that states an effect says how far its probabilities have held on blind worlds and what to run next
    assert doc["verdict"] != "consistent" and "`labctl plan`" in doc["verdict_text"]
    assert "labctl plan" not in run_discrepancy(null_points).verdict_text()


def test_a_pair_it_states_says_it_may_be_one_effect_in_a_form_the_library_lacks():
    # below about 1 % scatter the blind worlds' single effects were named as pairs, a second term mending the
    # first one's law: a stated pair says so and what to run; a single term does not
    pair = run_discrepancy(synthesize(world(EndEffects(0.3e-3), Misalignment(tilt_rad=6e-4)),
                                      noise=NoiseModel(0.01, 0.004), seating_rel=0.002, seed=0))
    assert pair.scored[0].explanation.kind == "pair" and pair.scored[0].probability >= 0.5
    assert "one effect whose law the library lacks" in pair.verdict_text()
    single = run_discrepancy(synthesize(world(EndEffects(0.3e-3)), noise=NoiseModel(0.01, 0.004),
                                        seating_rel=0.002, seed=0))
    assert len(single.scored[0].explanation.terms) == 1
    assert "one effect whose law the library lacks" not in single.verdict_text()


def test_one_roller_type_says_what_the_data_cannot_separate():
    points = synthesize(world(EndEffects(0.3e-3)), types=[1], noise=NoiseModel(0.01, 0.004), seed=5)
    result = run_discrepancy(points)
    assert any("1 roller geometry" in r for r in result.reasons)
    assert "identifiability" in result.to_dict()["decision"]
    assert "1 roller geometry" in result.verdict_text()


def test_a_consistent_verdict_on_one_roller_type_still_says_what_its_design_cannot_test():
    # a tilt that this one roller closes below the campaign's loads: the baseline passes, and the verdict must not
    # read as if length-scaling terms had been tested
    result = run_discrepancy(synthesize(world(Misalignment(tilt_rad=4e-4)), types=[1], noise=GENERATOR_NOISE, seed=1))
    assert result.verdict == "consistent"
    text = result.verdict_text()
    assert "1 roller geometry" in text and "end_effects, misalignment" in text and "one rail roughness" in text


def test_a_load_gain_error_is_said_to_be_untestable_not_ruled_out():
    # Tripp's law sees the load only through ln of the contact half-width, as it sees the depth: a gain of 1.08
    # is taken up by the fitted depth, and "consistent" must not read as if the load cell had been checked
    truth = world()
    doc = run_discrepancy(synthesize(lambda case, f: truth(case, f / 1.08), noise=GENERATOR_NOISE, seed=5)).to_dict()
    assert doc["verdict"] == "consistent" and doc["measurement_effects"] == []
    assert any(r.startswith("load_gain: ") and "cannot test it" in r for r in doc["decision"]["identifiability"])
    assert "load_gain: it changes every stiffness as the baseline's evaluation depth does" in doc["verdict_text"]
    assert not any(r.startswith(("load_offset", "modulus_scale")) for r in doc["decision"]["identifiability"])


def test_a_load_gain_the_depth_takes_up_is_no_design_limit_for_two_candidates_alike():
    # seven roller types on two rails: nothing in the design keeps end effects from an unnamed term, so why the
    # data cannot separate them is their likeness, not "the design's limits" (the untestable gain is no such limit)
    truth, noise = world(EndEffects(0.05e-3)), NoiseModel(low=0.06, high=0.02)
    points = synthesize(truth, noise=noise, seed=0) + synthesize(truth, rail_ra_m=0.03e-6, noise=noise, seed=100)
    text = run_discrepancy(points).verdict_text()
    assert "the data cannot separate end_effects from unlisted: their signatures are alike" in text
    assert "load_gain: it changes every stiffness as the baseline's evaluation depth does" in text


def test_ball_rows_are_refused_with_one_line(tmp_path, null_points):
    p = null_points[0]
    ball = dataclasses.replace(p, diameter_m=8e-3, contact_length_m=8e-3, roller_length_m=8e-3, roller_type=None)
    path = tmp_path / "mixed.csv"
    write_stiffness_table(path, [p, ball])
    with pytest.raises(InputError, match=r"row 3: .* is a ball .*Hertz") as exc:
        load_points([path])
    assert "\n" not in str(exc.value)


def test_a_ball_series_in_a_campaign_file_is_refused_with_one_line(tmp_path):
    """A campaign's specimen is a typed SpecimenRecord: a ball series is named and refused (it was read as a dict)."""
    from labctl.discrepancy.data import load_points
    from labctl.storage import CampaignWriter
    from labctl.storage.specimen import SpecimenRecord

    path = tmp_path / "balls.h5"
    writer = CampaignWriter.create(path, protocol_name="ball_verification", backend="sim", seed=1,
                                   config_files={"protocol.toml": "", "rig.toml": ""}, description={})
    writer.series(1, SpecimenRecord(kind="ball", label="ball 8 mm", ball_diameter_m=8e-3, diameter_m=8e-3,
                                    contact_length_m=8e-3, rail_ra_m=0.2e-6))
    writer.close()
    with pytest.raises(InputError, match=r"series 1 is a ball run \(ball 8 mm, diameter 8 mm\)") as exc:
        load_points([path])
    assert "\n" not in str(exc.value)


def test_a_baseline_the_lack_of_fit_test_rejects_leaves_none_no_probability():
    """A tilt on a blind world (bench/blind, misalignment, seed 0, noise 0.5×): the baseline fails the lack-of-fit
    test by far, yet the tempered evidence used to leave "none" the most probable explanation (0.55) under an
    "unexplained" verdict."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
    from discrepancy_blind import blind_worlds, csv_points

    from labctl.discrepancy.noise import CONSISTENT_P

    result = run_discrepancy(csv_points(blind_worlds("blind").generate("misalignment", 0, 0.5).rows))
    assert result.baseline_lack_of_fit_p < CONSISTENT_P
    probability = {s.explanation.name: s.probability for s in result.scored}
    assert probability["none"] == 0.0 and result.scored[0].explanation.name != "none"
    assert math.isclose(sum(probability.values()), 1.0)
    assert "none" not in result.verdict_text().split("most probable explanations:")[-1]


def test_a_shape_parameter_can_be_freed_alone():
    """The shape doubt frees one shape parameter of a term at a time (each departure from the law alone): a spec with
    one of the end term's two freed fits that one only; both freed fit both, in the term's order."""
    spec = ModelSpec().with_effects("end_effects")
    assert set(FIT_ONLY_BOUNDS["end_effects"]) == {"half_width_share", "radius_share"}
    one = [k for _, k, *_ in spec.with_free_shape("end_effects", "radius_share").slots()]
    assert one == ["edge_length_m", "radius_share"]
    both = [k for _, k, *_ in spec.with_free_shape("end_effects", "radius_share")
            .with_free_shape("end_effects", "half_width_share").slots()]
    assert both == ["edge_length_m", "half_width_share", "radius_share"]
    assert [k for _, k, *_ in spec.slots()] == ["edge_length_m"]
