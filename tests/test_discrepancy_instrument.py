"""An instrument error is one value for every roller: the measurement-side terms' consistency check."""

from __future__ import annotations

import pytest

from labctl.discrepancy import build_dataset, run_discrepancy
from labctl.discrepancy.instrument import CONSISTENCY_LEVEL, check_instrument
from labctl.discrepancy.model import ModelSpec, fit_model
from labctl.discrepancy.noise import estimate_noise
from labctl.discrepancy.synthetic import synthesize
from tests.discrepancy_util import GENERATOR_NOISE, world


def with_offset(inner, offset_of):
    """Measured stiffness when the recorded load is the true load + ``offset_of(case)``."""
    return lambda case, load_n: inner(case, load_n - offset_of(case))


def offset_check(truth, seed):
    """The load-offset model fitted to a simulated campaign, and its instrument check."""
    data = build_dataset(synthesize(truth, noise=GENERATOR_NOISE, seed=seed))
    noise = estimate_noise(data)
    fit = fit_model(data, ModelSpec().with_effects("load_offset"), sigma=noise.sigma_at(data),
                    seating_sigma=noise.seating_sigma)
    (check,) = check_instrument(data, fit, noise)
    return check


def test_one_load_cell_offset_for_every_roller_passes_the_instrument_check():
    check = offset_check(with_offset(world(), lambda case: 15.0), seed=43)
    assert check.passed and check.p >= CONSISTENCY_LEVEL and not check.at_bound
    assert len(check.values) == 7
    assert all(v == pytest.approx(15.0, abs=4 * s) for v, s in zip(check.values, check.sigmas, strict=True))
    # the workflow checks the explanation it ranks first, and keeps it
    result = run_discrepancy(synthesize(with_offset(world(), lambda case: 15.0), noise=GENERATOR_NOISE, seed=43))
    top = result.scored[0]
    assert "load_offset" in top.explanation.name and all(c["passed"] for c in top.extra["instrument"])


def test_an_offset_that_differs_by_roller_type_is_no_instrument_error():
    # 20 N per 10 mm of contact length: an "offset" the load cell cannot have, since it reads every roller alike
    check = offset_check(with_offset(world(), lambda case: 2e3 * case.roller.contact_length_m), seed=44)
    assert not check.passed and check.p < CONSISTENCY_LEVEL
    assert "differs by roller type" in check.describe()


def test_an_offset_beyond_its_range_is_said_to_be_pinned():
    check = offset_check(with_offset(world(), lambda case: -120.0), seed=45)
    assert check.at_bound and not check.passed
    assert "end of its range" in check.describe()
