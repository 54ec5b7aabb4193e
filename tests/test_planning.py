"""``labctl plan``: the next measurement chosen to separate the candidate effects, within what the rig and the
catalogue allow, and a clear "enough" when nothing would change the verdict."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from labctl.discrepancy.synthetic import NoiseModel, synthesize
from labctl.physics import ContactLaw, EndEffects, SurfaceRoughness, load_rig, material, rollers
from labctl.physics.rating import static_load_rating_n
from labctl.planning import plan_measurements
from labctl.planning.criterion import ModelAt, greedy_loads, score_sets, set_noise
from labctl.planning.rivals import Rival
from labctl.planning.specimens import RAIL_RA_UM, reachable_loads
from labctl.protocol import load_protocol
from labctl.stiffness_table import write_stiffness_table
from tests.cli_util import assert_one_line_error, labctl_here, labctl_here_json

NOISE = NoiseModel(0.02, 0.007)
STEEL = material("1.3505")


def _rough_and_ends(case, load_n):
    return ContactLaw("tripp", 1.5e-3, (SurfaceRoughness(1.5), EndEffects(0.1e-3))).stiffness_n_per_m(case, load_n)


def _rough(case, load_n):
    return ContactLaw("tripp", 1.5e-3, (SurfaceRoughness(1.5),)).stiffness_n_per_m(case, load_n)


@pytest.fixture(scope="module")
def short_roller_csv(tmp_path_factory):
    """Type 1 (L_we 1.79 mm) alone on Ra 0.2 µm rails, roughness and end effects present."""
    path = tmp_path_factory.mktemp("plan") / "type1.csv"
    write_stiffness_table(path, synthesize(_rough_and_ends, types=[1], noise=NOISE, seed=1))
    return path


@pytest.fixture(scope="module")
def short_roller_plan(short_roller_csv):
    from labctl.discrepancy import load_points

    return plan_measurements(load_points([short_roller_csv]))


def test_one_short_roller_top_recommendation_is_a_clearly_different_length(short_roller_plan):
    plan = short_roller_plan
    assert not plan.enough
    top = plan.recommendations[0]
    measured = rollers()[1].contact_length_m
    ratio = rollers()[top.roller_type].contact_length_m / measured
    assert ratio >= 2 or ratio <= 0.5, (top, ratio)
    assert f"type {top.roller_type}" in top.reason and ("longer" in top.reason or "shorter" in top.reason)
    assert "\n" not in top.reason
    # the reason names the models the measurement separates, among those the plan weighs
    named = [t for t in ("end_effects", "surface_roughness", "misalignment", "material_hardness",
                         "setup_compliance", "load_gain", "load_offset", "modulus_scale") if t in top.reason]
    assert named and all(any(t in label for label in plan.in_play) for t in named)
    scores = [r.score for r in plan.recommendations]
    assert scores == sorted(scores, reverse=True) and scores[0] > 0


def test_recommendations_are_catalogue_types_at_loads_the_rig_reaches(short_roller_plan):
    protocol, rig = load_protocol("roller_stiffness"), load_rig()
    per_step = rig.load_per_knob_degree_n * protocol.loading.knob_step_deg
    for r in short_roller_plan.recommendations:
        assert r.roller_type in rollers() and r.rail_ra_um in RAIL_RA_UM
        cap = protocol.loading.max_load_fraction_c0 * static_load_rating_n(rollers()[r.roller_type], STEEL)
        loads = np.array(r.loads_n)
        assert 1 <= loads.size <= 5 and np.all(np.diff(loads) > 0)
        assert loads.max() <= cap and loads.min() >= rig.preload_per_roller_n - 0.1
        steps = (loads - rig.preload_per_roller_n) / per_step
        assert np.allclose(steps, np.round(steps), atol=0.01), steps  # whole knob steps (multiples of 180°)


def test_reachable_loads_follow_the_rig_and_the_protocol_cap():
    protocol, rig = load_protocol("roller_stiffness"), load_rig()
    loads, cap = reachable_loads(protocol, 1, STEEL, 0.2e-6, rig)
    fraction = protocol.loading.max_load_fraction_c0
    assert cap == pytest.approx(fraction * static_load_rating_n(rollers()[1], STEEL))
    assert loads[0] == pytest.approx(rig.preload_per_roller_n)
    assert np.diff(loads) == pytest.approx(rig.load_per_knob_degree_n * 180.0)
    assert loads[-1] <= cap < loads[-1] + rig.load_per_knob_degree_n * 180.0
    stiff = replace(rig, loading=replace(rig.loading, spring_rate_n_per_m=2 * rig.loading.spring_rate_n_per_m))
    coarse, _ = reachable_loads(protocol, 1, STEEL, 0.2e-6, stiff)
    assert np.diff(coarse) == pytest.approx(2 * rig.load_per_knob_degree_n * 180.0)
    low = replace(protocol, loading=replace(protocol.loading, max_load_fraction_c0=0.1))
    capped, cap_low = reachable_loads(low, 1, STEEL, 0.2e-6, rig)
    assert capped.max() <= cap_low == pytest.approx(cap * 0.1 / fraction)


def test_data_consistent_with_one_well_determined_effect_needs_no_more_measurement():
    """The paper's programme (types 1-7 on both rails) on a world with roughness only: enough."""
    points = []
    for seed, ra in enumerate((0.2e-6, 0.03e-6)):
        points += synthesize(_rough, types=range(1, 8), rail_ra_m=ra, noise=NOISE, seed=seed, repetitions=2,
                             steps=8)
    plan = plan_measurements(points)
    assert plan.result.verdict == "explained" and [s.name for s in plan.result.steps] == ["surface_roughness"]
    assert plan.enough
    assert plan.to_dict()["enough"] is True


def _model(mu, cov_diag, weight=0.5):
    mu = np.asarray(mu, dtype=float)
    rival = Rival((), lambda d, x: mu, np.zeros(1), np.zeros(1), np.ones(1), np.ones(1), 0.0,
                  np.array([[1.0]]))
    return ModelAt(rival, weight, mu, np.sqrt(np.asarray(cov_diag, dtype=float))[:, None], np.arange(0))


def test_the_criterion_is_the_box_hill_divergence():
    """Two models, one point: KL(N(a, s1) || N(b, s2)) = ½(s1/s2 − 1 + (a−b)²/s2 + ln(s2/s1))."""
    sigma2 = 0.02**2
    a, b = _model([0.1, 0.0], [0.0, 0.0]), _model([0.05, 0.0], [0.03**2, 0.0])
    noise = np.diag([sigma2, sigma2])
    sc = score_sets([a, b], noise, np.array([[0], [1]]))
    s1, s2 = sigma2, sigma2 + 0.03**2
    kl_ab = 0.5 * (s1 / s2 - 1 + 0.05**2 / s2 + math.log(s2 / s1))
    kl_ba = 0.5 * (s2 / s1 - 1 + 0.05**2 / s1 + math.log(s1 / s2))
    assert sc.kl[(0, 1)][0] == pytest.approx(kl_ab) and sc.kl[(1, 0)][0] == pytest.approx(kl_ba)
    assert sc.discrimination[0] == pytest.approx(0.25 * (kl_ab + kl_ba))
    assert sc.discrimination[1] == pytest.approx(0.0)  # where the models agree, nothing to learn


def test_two_points_at_one_load_share_the_seating_offset_only():
    """Noise of a set with a repeated load: σ² + τ² on the diagonal, τ² between the two repeats."""
    sigma2, tau2 = np.array([4e-4, 1e-4]), 9e-4
    noise = np.diag(sigma2) + tau2
    cov = set_noise(noise, np.array([[0, 0, 1]]), sigma2)[0]
    assert cov == pytest.approx(np.array([[4e-4 + tau2, tau2, tau2], [tau2, 4e-4 + tau2, tau2],
                                          [tau2, tau2, 1e-4 + tau2]]))


def test_the_greedy_choice_repeats_the_most_informative_load_when_allowed():
    """One parameter, sensitive at load 0 only: a second point there halves its variance, a point at load 1
    adds almost nothing, so with repeats allowed the best two loads are load 0 twice (distinct: 0 and 1)."""
    rival = Rival(("a",), lambda d, x: np.zeros(2), np.zeros(1), -np.ones(1), np.ones(1), np.ones(1), 0.0,
                  np.array([[1.0]]))
    model = ModelAt(rival, 1.0, np.zeros(2), np.array([[1.0], [0.05]]), np.arange(1))
    noise = np.diag([0.1**2, 0.1**2])
    repeated, score = greedy_loads([model], noise, 2, repeat=True)
    distinct, score_distinct = greedy_loads([model], noise, 2)
    assert list(repeated) == [0, 0] and list(distinct) == [0, 1]
    assert score.total[0] > score_distinct.total[0]
    assert score.total[0] == pytest.approx(0.5 * math.log(1 + 2 / 0.1**2))  # ½ ln(var before / var after)


def test_cli_json_is_exactly_the_contract(capsys, short_roller_csv):
    out = labctl_here_json(capsys, "plan", str(short_roller_csv), "--budget-steps", "3",
                           "--candidates", "end_effects,surface_roughness")
    assert set(out) == {"recommendations", "enough"} and isinstance(out["enough"], bool)
    assert out["recommendations"]
    for r in out["recommendations"]:
        assert set(r) == {"roller_type", "rail_ra_um", "loads_n", "reason", "score"}
        assert len(r["loads_n"]) <= 3
    top = out["recommendations"][0]
    ratio = rollers()[top["roller_type"]].contact_length_m / rollers()[1].contact_length_m
    # a clearly different length is what separates the two; the reason names the candidate the data favour now
    assert (ratio >= 2 or ratio <= 0.5) and ("end_effects" in top["reason"] or "surface_roughness" in top["reason"])


@pytest.mark.parametrize("args, fragments", [
    (["--budget-steps", "0"], ["--budget-steps", "at least 1"]),
    (["--budget-steps", "two"], ["--budget-steps", "'two'"]),
    (["--candidates", "lubrication"], ["--candidates", "'lubrication'", "end_effects"]),
    (["--candidates", ","], ["--candidates", "expected 'all'"]),
    (["--protocol", "ball_verification"], ["--protocol", "roller protocol"]),
    (["--protocol", "nowhere.toml"], ["nowhere.toml", "not found"]),
    (["--rig", "no_rig.toml"], ["no_rig.toml"]),
])
def test_bad_options_are_one_line_errors(capsys, short_roller_csv, args, fragments):
    assert_one_line_error(labctl_here(capsys, "plan", str(short_roller_csv), *args), *fragments)


def test_bad_data_is_a_one_line_error_naming_the_file(capsys, tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("diameter_mm,contact_length_mm,rail_ra_um,load_n,stiffness_n_per_m\n3,1.793,0.2,-5,1e8\n")
    assert_one_line_error(labctl_here(capsys, "plan", str(bad)), "bad.csv", "load_n")
    assert_one_line_error(labctl_here(capsys, "plan", str(tmp_path / "none.csv")), "none.csv", "not found")


def test_an_unnamed_empirical_term_is_pinned_down_at_the_extremes_of_its_feature():
    """A stiffness that grows as D^0.15 (no library term): the workflow proposes ln(D/D0); the plan says more
    data are needed and picks the catalogue's thickest or thinnest roller to pin the coefficient down."""
    law = ContactLaw("tripp", 1.5e-3)

    def truth(case, load_n):
        return law.stiffness_n_per_m(case, load_n) * (case.roller.diameter_m / 5e-3) ** 0.15

    plan = plan_measurements(synthesize(truth, types=range(1, 8), noise=NOISE, seed=3, repetitions=2, steps=8))
    assert plan.result.empirical is not None and "ln(D/D0)" in plan.result.empirical.features
    assert not plan.enough
    top = plan.recommendations[0]
    diameters = [r.diameter_m for r in rollers().values()]
    assert rollers()[top.roller_type].diameter_m in (min(diameters), max(diameters))
    assert "unnamed empirical term (ln(D/D0))" in top.reason


def test_loads_a_model_in_play_cannot_predict_are_not_proposed():
    from labctl.planning.plan import _predictable
    from labctl.planning.specimens import Specimen

    def offset_model(data, x):  # a load-cell offset of 50 N: no true load below it
        load = np.concatenate([c.load_n for c in data.cases])
        return np.where(load > 50.0, np.log(load), np.nan)

    rival = Rival(("load_offset",), offset_model, np.zeros(1), np.zeros(1), np.ones(1), np.ones(1), 0.0)
    spec = Specimen(rollers()[1], STEEL, 0.2e-6, np.array([37.9, 78.4, 118.9]), 434.0)
    kept = _predictable(spec, [rival])
    assert kept is not None and list(kept.loads_n) == [78.4, 118.9]
    assert _predictable(replace(spec, loads_n=np.array([37.9])), [rival]) is None


def test_a_file_that_is_no_campaign_is_a_one_line_error(capsys, tmp_path):
    path = tmp_path / "campaign.h5"
    path.write_bytes(b"not hdf5")
    assert_one_line_error(labctl_here(capsys, "plan", str(path)), "campaign.h5")


def test_cli_loads_follow_the_given_rig_file(capsys, short_roller_csv, tmp_path):
    """A rig with springs twice as stiff: every recommended load is a whole number of its (larger) knob steps."""
    from labctl.data import data_path

    text = data_path("rigs/paper_rig.toml").read_text()
    assert "spring_rate_n_per_m = 4.05e4" in text
    rig_file = tmp_path / "stiff_springs.toml"
    rig_file.write_text(text.replace("spring_rate_n_per_m = 4.05e4", "spring_rate_n_per_m = 8.1e4"))
    out = labctl_here_json(capsys, "plan", str(short_roller_csv), "--rig", str(rig_file), "--budget-steps", "2",
                           "--candidates", "end_effects")
    rig = load_rig(rig_file)
    per_step = rig.load_per_knob_degree_n * load_protocol("roller_stiffness").loading.knob_step_deg
    assert per_step == pytest.approx(2 * load_rig().load_per_knob_degree_n * 180.0)
    for r in out["recommendations"]:
        steps = (np.array(r["loads_n"]) - rig.preload_per_roller_n) / per_step
        assert np.allclose(steps, np.round(steps), atol=0.01), (r, steps)


def test_a_reason_gives_one_line_load_when_every_planned_load_is_the_same():
    from labctl.planning.plan import _design_data, _load_words
    from labctl.planning.specimens import Specimen

    spec = Specimen(rollers()[1], STEEL, 0.2e-6, np.array([37.9, 159.4, 382.0]), 400.0)
    data = _design_data(spec)
    same = _load_words(np.array([37.9, 37.9, 37.9]), spec, data)
    assert "(21.1 N/mm)" in same and "–" not in same, same
    spread = _load_words(np.array([37.9, 382.0]), spec, data)
    assert "(21.1–213 N/mm)" in spread, spread


def test_a_kinked_parameter_is_spread_over_the_kink_positions_the_data_allow(tmp_path):
    """Hardness onset at 310 N (type 1, gain 0.3, threshold 0.30): with four levels above the onset the kink
    grid's mixture gives the gain the linearised SE (the kink lies between loads, the grid is refined around it);
    with one level above it the gain and the onset trade off and the mixture's SD is many times larger."""
    from labctl.discrepancy.data import build_dataset
    from labctl.discrepancy.model import ModelSpec, fit_model
    from labctl.discrepancy.noise import estimate_noise
    from labctl.physics import MaterialHardness
    from labctl.planning.rivals import from_fit, kink_posterior
    from labctl.stiffness_table import StiffnessPoint
    from tests.engine_util import stepped_protocol_text

    proto = tmp_path / "onset.toml"
    proto.write_text(stepped_protocol_text("onset", roller_type=1, max_load=400.0, max_steps=3, reps=2))
    spec = load_protocol(proto).specimens[0]
    case = spec.case()
    law = ContactLaw("tripp", 1.5e-3, (MaterialHardness(0.3, 0.30),))
    model = ModelSpec("tripp", ("material_hardness",))

    def gain(loads):
        rng = np.random.default_rng(1)
        points = []
        for rep in (1, 2):
            seat = 1e-3 * rng.standard_normal()
            for f in loads:
                k = float(law.stiffness_n_per_m(case, f)) * np.exp(seat + 3e-4 * rng.standard_normal())
                points.append(StiffnessPoint(case.roller.diameter_m, case.roller.contact_length_m, spec.rail_ra_m,
                                             f, k, roller_type=1, repetition=rep))
        data = build_dataset(points)
        noise = estimate_noise(data)
        sigma = noise.sigma_at(data)
        fit = min((fit_model(data, model, sigma=sigma, seating_sigma=noise.seating_sigma, guess=g)
                   for g in (None, {"material_hardness": {"gain": 0.15, "threshold": 0.3}})),
                  key=lambda f: float(np.sum(f.z**2)))

        def whiten(a):
            return noise.whiten(data, a, sigma)

        rival = from_fit(fit)
        assert rival.kink == 2
        laplace = float(np.sqrt(rival.with_covariance(data, whiten).covariance[1, 1]))
        return kink_posterior(rival, 1, data, whiten), laplace

    dense, laplace = gain([37.9, 159.4, 280.9, 321.0, 341.6, 361.9, 382.2])
    assert dense.sd == pytest.approx(laplace, rel=0.3)
    lo, hi = model.slots()[0][2:]  # the gain's fitted range (signed: yield softening is allowed)
    assert abs(lo + (hi - lo) * dense.mean - 0.3) < 3 * (hi - lo) * dense.sd
    assert abs(0.05 + 0.95 * dense.kink_mean - 0.30) < 0.002
    bracketed, _ = gain([37.9, 159.4, 280.9, 382.2])
    assert bracketed.sd > 20 * dense.sd


def test_a_person_at_a_terminal_is_told_the_plan_is_being_computed(capsys, monkeypatch, short_roller_csv):
    """`labctl plan` was silent for tens of seconds; at a terminal it says so once its inputs are read."""
    import sys

    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    proc = labctl_here(capsys, "plan", str(short_roller_csv), "--budget-steps", "2", "--candidates",
                       "end_effects,surface_roughness")
    assert proc.returncode == 0 and proc.stderr.startswith(f"planning: scoring candidate rollers, rails and loads "
                                                           f"for {short_roller_csv}")
