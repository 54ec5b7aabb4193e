"""A library term in a free form: its physical signature kept, its load law left to the data."""

from __future__ import annotations

import numpy as np
import pytest

from labctl.discrepancy import run_discrepancy
from labctl.discrepancy.empirical import BASIS
from labctl.discrepancy.free_form import FREE_FORM_DOUBT, SIGNATURES, averaged, signature
from labctl.discrepancy.synthetic import NoiseModel, synthesize
from labctl.physics import ContactCase, ContactLaw


def test_every_signature_feature_is_in_the_basis():
    assert {f for fs in SIGNATURES.values() for f in fs} <= set(BASIS)


def test_a_free_form_needs_a_signature_for_every_term():
    assert signature(("end_effects",)) == SIGNATURES["end_effects"]
    both = signature(("surface_roughness", "end_effects"))
    assert both is not None and set(both) == set(SIGNATURES["surface_roughness"]) | set(SIGNATURES["end_effects"])
    assert signature(("misalignment",)) is None
    assert signature(("end_effects", "setup_compliance")) is None
    assert signature(("end_effects", "load_offset")) is None  # a calibration error has an exact form
    assert signature(()) is None


def test_the_evidence_is_the_prior_weighted_average_of_the_two_forms():
    law, free = {4.0: -10.0}, {4.0: -7.0}
    expected = np.log((1 - FREE_FORM_DOUBT) * np.exp(-10.0) + FREE_FORM_DOUBT * np.exp(-7.0))
    assert averaged(law, free)[4.0] == pytest.approx(expected)
    assert averaged(law, {4.0: -1e9})[4.0] == pytest.approx(-10.0 + np.log(1 - FREE_FORM_DOUBT))


def stiffening_film(case: ContactCase, f: np.ndarray) -> np.ndarray:
    """Tripp in series with a film on the rails whose compliance per length, 4·10⁻¹² m²/N at p·R = 10 N, falls as
    (p·R)^-½ whatever the roughness: no library term's signature."""
    p_r = f / case.roller.contact_length_m * case.roller.radius_m
    compliance = 4e-12 * np.sqrt(10.0 / p_r) / case.roller.contact_length_m
    return 1.0 / (1.0 / ContactLaw("tripp", 2e-3).stiffness_n_per_m(case, f) + compliance)


def test_a_film_with_no_library_signature_is_not_named():
    result = run_discrepancy(synthesize(stiffening_film, noise=NoiseModel(0.02, 0.02 / 3), seed=2))
    doc = result.to_dict()
    assert doc["effects"] == [] and doc["measurement_effects"] == []
