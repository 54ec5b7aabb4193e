"""Names on effects whose form differs from the library's: the structure an imperfect term leaves is its form's,
not evidence of a second effect or a calibration error, and bad rows do not change the verdict."""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from labctl.discrepancy import run_discrepancy
from labctl.discrepancy.synthetic import NoiseModel, synthesize
from labctl.physics import ContactCase, ContactLaw, Misalignment, SetupCompliance
from tests.discrepancy_util import GENERATOR_NOISE, world


def joint_spring(depth_m: float, k_joint: float, beta: float):
    """Tripp with an extra joint spring in series that stiffens with load as F^β (not the library's
    setup_compliance form, which is a constant K_setup error)."""
    inner = ContactLaw("tripp", depth_m).stiffness_n_per_m

    def k(case: ContactCase, f: np.ndarray) -> np.ndarray:
        return 1.0 / (1.0 / inner(case, f) + 1.0 / (k_joint * (f / 100.0) ** beta))
    return k


def campaign(depth_m: float, k_joint: float, beta: float, low: float, seed: int):
    return synthesize(joint_spring(depth_m, k_joint, beta), noise=NoiseModel(low, low / 3.0), seed=seed,
                      seating_rel=0.1 * low)


@pytest.mark.parametrize("args", [(2.05e-3, 7.1e8, 0.10, 0.016, 415), (3.09e-3, 2.9e8, 0.021, 0.015, 413),
                                  (3.05e-3, 2.29e8, 0.171, 0.0127, 402)], ids=["beta-0.10", "beta-0.02", "beta-0.17"])
def test_a_setup_spring_of_another_form_is_the_setup_term_and_gets_no_second_name(args):
    # A joint spring stiffening as F^β is not the library's constant K_setup error: the term's bent form carries
    # it, so the most probable explanation is setup_compliance alone — never a load offset, modulus scale or a
    # second physical term for the leftover of its form.
    result = run_discrepancy(campaign(*args))
    doc = result.to_dict()
    assert any(x.explanation.name == "setup_compliance" for x in result.scored[:3])
    assert [e["name"] for e in doc["effects"]] in ([], ["setup_compliance"])
    assert doc["measurement_effects"] == []
    if not doc["consistent_with_noise"]:
        assert "NOT consistent" in doc["verdict_text"]

def bulk_yield(case: ContactCase, f: np.ndarray) -> np.ndarray:
    """Tripp softened once p_max passes 0.2 of the softer body's hardness, exponentially and whatever the
    surface (the library's yield term is linear in the excess and scales with the combined roughness)."""
    excess = np.maximum(0.0, case.peak_pressure_pa(f) / (0.2 * case.softer_hardness_pa) - 1.0)
    return ContactLaw("tripp", 2e-3).stiffness_n_per_m(case, f) * np.exp(-0.25 * excess)


def test_a_yield_blind_to_the_surface_is_the_hardness_term_where_one_rail_is_smoother():
    # Two roller types on a 0.03 µm rail, five on 0.2 µm: a yield term bound to the roughness predicts almost no
    # effect on the smooth rail, and the world was called an effect outside the library at 1.00 (now hardness 0.90).
    noise = NoiseModel(0.02, 0.02 / 3)
    points = (synthesize(bulk_yield, types=(1, 6), rail_ra_m=0.03e-6, noise=noise, seed=5)
              + synthesize(bulk_yield, types=(2, 3, 4, 5, 7), noise=noise, seed=6))
    result = run_discrepancy(points)
    top = result.scored[0]
    assert top.explanation.name == "material_hardness" and top.probability > 0.5


def boussinesq_ends(case: ContactCase, f: np.ndarray) -> np.ndarray:
    """Tripp over a loaded length L + 2κa: each end's stress field carries an extra strip 1.5 half-widths wide,
    which grows with load (the library's end term adds a fixed length)."""
    a = np.sqrt(4.0 * f / case.roller.contact_length_m * case.roller.radius_m / (np.pi * case.effective_modulus_pa))
    return ContactLaw("tripp", 2e-3).stiffness_n_per_m(case, f) * (1.0 + 3.0 * a / case.roller.contact_length_m)


def test_ends_that_grow_with_the_contact_width_are_the_end_term_not_an_effect_outside_the_library():
    # Before the end term's edge could follow the half-width: "unlisted" 0.86, end_effects 0.06 (now 0.85: likely).
    result = run_discrepancy(synthesize(boussinesq_ends, noise=NoiseModel(0.02, 0.02 / 3), seed=0))
    top = result.scored[0]
    assert top.explanation.name == "end_effects" and top.probability > 0.5 and top.fit is not None
    assert top.fit.spec.decode(top.fit.x)["end_effects"]["half_width_share"] == pytest.approx(1.5, rel=0.2)


def fractal_asperities(case: ContactCase, f: np.ndarray) -> np.ndarray:
    """Tripp in series with fractal asperities, k_asp = E*·L·(p/(E*·Ra))^½/3: they stiffen as p^½ where the
    library's exponential tail stiffens ∝ p."""
    e, length = case.effective_modulus_pa, case.roller.contact_length_m
    k_asp = e * length * np.sqrt(f / length / (e * case.combined_ra_m)) / 3.0
    return 1.0 / (1.0 / ContactLaw("tripp", 2e-3).stiffness_n_per_m(case, f) + 1.0 / k_asp)


def test_asperities_that_stiffen_more_slowly_are_the_roughness_term_not_an_effect_outside_the_library():
    # Before the roughness term's load exponent was in doubt: "unlisted" 1.00 (now surface_roughness 0.85).
    result = run_discrepancy(synthesize(fractal_asperities, noise=NoiseModel(0.02, 0.02 / 3), seed=0))
    top = result.scored[0]
    assert top.explanation.name == "surface_roughness" and top.probability > 0.5 and top.fit is not None
    assert top.fit.spec.decode(top.fit.x)["surface_roughness"]["load_exponent"] == pytest.approx(0.5, abs=0.1)


def rough_joint(case: ContactCase, f: np.ndarray) -> np.ndarray:
    """Tripp in series with a rough flat joint in the rig's load path: its compliance 3·10⁻¹⁰ m/N at 100 N per
    roller falls as 1/F, the same for every roller (an exponential asperity tail, in the rig, not the contact)."""
    return 1.0 / (1.0 / ContactLaw("tripp", 2e-3).stiffness_n_per_m(case, f) + 3e-10 * 100.0 / f)


@pytest.fixture(scope="module")
def one_rail_joint():
    """The rough rig joint on one rail, all seven roller types (run once for the tests that read its verdict)."""
    return run_discrepancy(synthesize(rough_joint, noise=GENERATOR_NOISE, seed=3))


def test_one_rail_roughness_says_roughness_cannot_be_told_from_a_rig_joint(one_rail_joint):
    # On one rail every contact has the same composite Ra, and an asperity layer's compliance ∝ Ra/F is then the
    # same for every roller, as a joint's in the rig's load path: the world is ranked surface_roughness, and the
    # verdict must say the design cannot tell the two apart (before: only that Ra-dependence was not tested).
    one = one_rail_joint
    assert one.scored[0].explanation.name == "surface_roughness"
    assert "a joint in the rig's load path" in one.verdict_text()
    two = run_discrepancy(synthesize(rough_joint, types=(1, 3, 5), rail_ra_m=0.03e-6, noise=GENERATOR_NOISE, seed=4)
                          + synthesize(rough_joint, types=(2, 4, 6, 7), noise=GENERATOR_NOISE, seed=5))
    assert "a joint in the rig's load path" not in two.verdict_text()


def test_a_likely_or_named_term_says_what_else_acts_like_it(one_rail_joint):
    # On the blind judges a compliant interlayer under the rails is most probably setup_compliance and a porous
    # layer on them surface_roughness (docs/discrepancy.md): a verdict that finds either term likely says so.
    rough = one_rail_joint
    assert rough.scored[0].explanation.name == "surface_roughness" and rough.verdict == "likely"
    assert "surface_roughness may also be any other compliant layer on the surfaces" in rough.verdict_text()
    rig = run_discrepancy(synthesize(world(SetupCompliance(stiffness_factor=0.7)), noise=GENERATOR_NOISE, seed=49))
    assert rig.scored[0].explanation.name == "setup_compliance" and rig.scored[0].probability >= 0.5
    assert "setup_compliance may also be a compliant layer under the rails" in rig.verdict_text()
    tilt = run_discrepancy(synthesize(world(Misalignment(tilt_rad=6e-4)), noise=GENERATOR_NOISE, seed=2))
    assert tilt.scored[0].explanation.name == "misalignment" and "may also be" not in tilt.verdict_text()
    # a load cell reading 15 N too much: likely load_offset (0.73), and a hard layer on the rails looks alike
    offset = run_discrepancy(synthesize(lambda case, f: world()(case, f - 15.0), noise=GENERATOR_NOISE, seed=43))
    assert offset.scored[0].explanation.name == "load_offset" and offset.scored[0].probability >= 0.5
    assert "load_offset may also be a hard coating" in offset.verdict_text()


def test_three_percent_outliers_leave_the_verdict_unchanged():
    # 7 of 231 points off by a factor e^±(0.2-0.5): all are set aside and reported, and setting them aside must
    # not let two measurement-side terms absorb what the imperfect setup term leaves. Before an end point was judged
    # against its step's other repetitions, type 7's lowest point (29 % off, 2.5 % noise) was kept.
    points = campaign(1.2e-3, 6.8e8, 0.091, 0.025, 401008)
    clean = run_discrepancy(points).to_dict()
    rng = np.random.default_rng(7)
    bad = list(points)
    for i in (129, 23, 227, 210, 92, 50, 198):
        factor = math.exp(float(rng.choice([-1.0, 1.0])) * float(rng.uniform(0.2, 0.5)))
        bad[i] = dataclasses.replace(bad[i], stiffness_n_per_m=bad[i].stiffness_n_per_m * factor)
    doc = run_discrepancy(bad).to_dict()
    assert len(doc["input_checks"]["outliers"]) == 7
    for key in ("effects", "measurement_effects"):
        assert [e["name"] for e in doc[key]] == [e["name"] for e in clean[key]]
    assert doc["verdict"] == clean["verdict"]


def crowned(depth_m: float, relief: float, drop_m: float):
    """A crowned roller: flat middle, parabolic end reliefs (``relief`` × L_we per end, dropping ``drop_m`` at the
    end) on an elastic bed of Tripp's stiffness per length; the contact length grows with load."""
    inner = ContactLaw("tripp", depth_m).stiffness_n_per_m

    def k(case: ContactCase, f: np.ndarray) -> np.ndarray:
        length = case.roller.contact_length_m
        per_length = inner(case, f) / length
        flat, ends = length * (1 - 2 * relief), length * relief

        def area(d: np.ndarray) -> np.ndarray:  # ∫ max(0, d − gap(x)) dx
            u = ends * np.sqrt(np.minimum(d / drop_m, 1.0))
            return d * flat + 2.0 * (d * u - drop_m * u**3 / (3.0 * ends**2))
        need = f / per_length
        lo, hi = np.zeros_like(need), need / flat
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            below = area(mid) < need
            lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
        d = 0.5 * (lo + hi)
        return per_length * (flat + 2.0 * ends * np.sqrt(np.minimum(d / drop_m, 1.0)))
    return k


@pytest.mark.parametrize(("depth_m", "relief", "drop_m", "low", "seed"),
                         [(1.07e-3, 0.176, 2.29e-6, 0.0133, 300018), (1.03e-3, 0.198, 2.16e-6, 0.0389, 300020)],
                         ids=["held-out-share", "held-out-rms"])
def test_crowned_rollers_are_not_named_surface_roughness(depth_m, relief, drop_m, low, seed):
    # On Ra 0.03 µm rails the asperity term explains most of a crowned roller's discrepancy in sample, but the
    # crowning's signature depends on length and diameter: roughness is never named, and what is left is stated.
    points = synthesize(crowned(depth_m, relief, drop_m), rail_ra_m=0.03e-6, noise=NoiseModel(low, low / 3),
                        seed=seed, seating_rel=0.1 * low)
    doc = run_discrepancy(points).to_dict()
    assert "surface_roughness" not in [e["name"] for e in doc["effects"]]
    assert doc["verdict"] in ("likely", "unexplained")
    assert "candidates" in doc["verdict_text"] and "NOT consistent" in doc["verdict_text"]
    assert doc["empirical_term"] is not None and doc["empirical_term"]["label"] == "unnamed"


def test_ends_whose_zone_scales_with_the_roller_radius_are_end_effects_alone():
    # An edge zone of 0.1·R at each end (k·(1 + 0.2·R/L_we), the ends' profile scaling with the roller), in the
    # test's own form. Before the end term's radius share, the library's fixed edge could not follow it across
    # roller types and a softening yield term mended it: "end_effects + material_hardness" at 0.97-0.99.
    def law(case: ContactCase, load_n: np.ndarray) -> np.ndarray:
        return world()(case, load_n) * (1.0 + 0.2 * case.roller.radius_m / case.roller.contact_length_m)

    result = run_discrepancy(synthesize(law, noise=GENERATOR_NOISE, seed=11))
    top = result.scored[0]
    assert top.explanation.name == "end_effects" and top.probability >= 0.5
    assert top.fit.effect_parameters()["end_effects"]["radius_share"] == pytest.approx(0.1, abs=0.02)
    assert "material_hardness" not in [e["name"] for e in result.to_dict()["effects"]]


@pytest.mark.parametrize(("scenario", "seed", "noise", "closest"),
                         [("surface_roughness", 2001, 1.0, "surface_roughness"),
                          ("outside_rate_dependence", 2000, 0.5, "end_effects")])
def test_an_unlisted_lead_names_the_library_term_closest_to_the_data(scenario, seed, noise, closest):
    """On the blind judge "unlisted" led as often for a library effect in a law unlike the library's (a roughness
    whose asperity heights fall off exponentially) as for an effect outside it (a rate dependence); the verdict
    says which library term is closest, and that the lead may be that term, in either case."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
    from discrepancy_blind import blind_worlds, csv_points

    result = run_discrepancy(csv_points(blind_worlds().generate(scenario, seed, noise).rows))
    assert result.scored[0].explanation.unlisted and result.scored[0].probability >= 0.9
    assert result.verdict == "unexplained" and result.closest.name == closest
    assert (f"\"unlisted\" may also be {closest} in a law unlike the library's (the library term closest to the "
            f"data: alone it takes up {result.closest.share:.0%} of the misfit)") in result.verdict_text()
