"""Contact models against the paper's numbers, textbook limits and numerical derivatives of their deflection."""

from __future__ import annotations

import numpy as np
import pytest

from labctl.errors import ModelDomainError
from labctl.physics import (
    EQ5,
    EQ6,
    EmpiricalFit,
    HertzBallContact,
    PalmgrenContact,
    TrippContact,
    effective_modulus,
    material,
    roller,
    static_load_rating_n,
)
from labctl.physics.catalogue import Roller

STEEL = material("1.3505")


def numerical_stiffness(model, load_n: np.ndarray) -> np.ndarray:
    h = 1e-4 * load_n
    return 2 * h / (model.deflection_m(load_n + h) - model.deflection_m(load_n - h))


def test_effective_modulus_steel_on_steel_is_114_6_gpa():
    assert effective_modulus(STEEL, STEEL) == pytest.approx(114.6e9, rel=1e-3)


def test_tripp_type1_at_440n_matches_design_value():
    k = TrippContact(roller(1), STEEL).stiffness_n_per_m(440.0)
    assert k == pytest.approx(4.376e7, rel=5e-3)


def test_tripp_depth_1_94mm_reproduces_fig6_spring():
    k = TrippContact(roller(1), STEEL, depth_m=1.94e-3).stiffness_n_per_m(440.0)
    assert k == pytest.approx(4.65e7, rel=1e-2)


@pytest.mark.parametrize("type_id", [1, 4, 8, 9])
def test_tripp_closed_form_equals_derivative_of_deflection(type_id):
    model = TrippContact(roller(type_id), STEEL, depth_m=2.5e-3)
    loads = np.geomspace(5.0, 3000.0, 17)
    np.testing.assert_allclose(model.stiffness_n_per_m(loads), numerical_stiffness(model, loads), rtol=1e-6)


def test_tripp_per_length_stiffness_independent_of_diameter_for_equal_materials():
    a = Roller(3e-3, 2e-3, 2.2e-3, STEEL)
    b = Roller(9e-3, 2e-3, 2.2e-3, STEEL)
    loads = np.array([20.0, 200.0, 900.0])
    np.testing.assert_allclose(TrippContact(a, STEEL).stiffness_n_per_m(loads),
                               TrippContact(b, STEEL).stiffness_n_per_m(loads), rtol=1e-12)


def test_tripp_stiffer_roller_material_gives_stiffer_contact_and_depth_softens():
    ceramic = TrippContact(roller(8), STEEL).stiffness_n_per_m(300.0)
    same_geometry_steel = TrippContact(Roller(3e-3, 2.756e-3, 2.8e-3, STEEL), STEEL).stiffness_n_per_m(300.0)
    assert ceramic > same_geometry_steel
    assert TrippContact(roller(1), STEEL, 5e-3).stiffness_n_per_m(300.0) < TrippContact(
        roller(1), STEEL, 2e-3).stiffness_n_per_m(300.0)


def test_palmgren_matches_its_power_law_and_derivative():
    model = PalmgrenContact(roller(1).contact_length_m)
    loads = np.array([50.0, 100.0, 400.0])
    delta_one_contact_mm = 3.84e-5 * 100.0**0.9 / 1.793**0.8
    assert model.deflection_m(100.0) == pytest.approx(2 * delta_one_contact_mm * 1e-3, rel=1e-12)
    np.testing.assert_allclose(model.stiffness_n_per_m(loads), numerical_stiffness(model, loads), rtol=1e-6)
    k = model.stiffness_n_per_m(loads)
    assert k[2] / k[0] == pytest.approx(8.0**0.1, rel=1e-9)


def test_hertz_ball_6mm_100n():
    model = HertzBallContact(6e-3, STEEL, STEEL)
    assert model.stiffness_n_per_m(100.0) == pytest.approx(1.44e7, rel=1e-2)
    loads = np.array([10.0, 100.0, 500.0])
    np.testing.assert_allclose(model.stiffness_n_per_m(loads), numerical_stiffness(model, loads), rtol=1e-6)
    k = model.stiffness_n_per_m(loads)
    assert k[1] / k[0] == pytest.approx(10.0 ** (1 / 3), rel=1e-9)  # k ∝ F^(1/3)


def test_empirical_fits_paper_values_and_crossing():
    length = roller(1).contact_length_m
    assert EmpiricalFit(EQ5, length).stiffness_n_per_m(440.0) == pytest.approx(4.540e7, rel=1e-3)
    assert EmpiricalFit(EQ6, length).stiffness_n_per_m(440.0) == pytest.approx(4.518e7, rel=1e-3)
    per_length = np.linspace(100e3, 400e3, 30001)  # N/m
    diff = np.log(per_length / EQ5.p0_n_per_m) * EQ5.c_n_per_m2 - np.log(per_length / EQ6.p0_n_per_m) * EQ6.c_n_per_m2
    crossing = per_length[np.argmin(np.abs(diff))]
    assert crossing == pytest.approx(230e3, rel=0.05)


def test_eq5_refuses_loads_below_its_validity_naming_the_limit():
    fit = EmpiricalFit(EQ5, roller(4).contact_length_m)
    with pytest.raises(ModelDomainError, match=r"1\.8 N/mm"):
        fit.stiffness_n_per_m(10.0)
    assert fit.stiffness_n_per_m(16.0) > 0


def test_models_refuse_nonpositive_loads():
    with pytest.raises(ModelDomainError):
        TrippContact(roller(1), STEEL).stiffness_n_per_m([100.0, -1.0])
    with pytest.raises(ModelDomainError):
        HertzBallContact(6e-3, STEEL, STEEL).stiffness_n_per_m(0.0)


def test_static_load_rating_type1():
    c0 = static_load_rating_n(roller(1), STEEL)
    assert c0 == pytest.approx(220 * 2.2 * 3.0, rel=0.01)
    assert 0.3 * c0 == pytest.approx(440.0, rel=0.02)  # the paper's top load for type 1
    assert static_load_rating_n(roller(1), STEEL, "contact") < c0


def test_catalogue_has_all_nine_types_with_table1_values():
    from labctl.physics import rollers

    cat = rollers()
    assert sorted(cat) == list(range(1, 10))
    assert cat[4].diameter_m == pytest.approx(9e-3)
    assert cat[4].contact_length_m == pytest.approx(8.309e-3)
    assert cat[8].material.youngs_modulus_pa == pytest.approx(300e9)
    assert cat[9].material.hardness_hrc == 54
