"""The evaluation bench's second tilt law (``bench/discrepancy_worlds.py``): the library's kinked law at a = 1, a
different law for a bed that stiffens with load."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from labctl.discrepancy.synthetic import case_for, protocol_loads
from labctl.physics import ContactLaw, Misalignment

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from discrepancy_worlds import tilt_on_stiffening_bed  # noqa: E402

INNER = ContactLaw("tripp", 2e-3).stiffness_n_per_m


@pytest.mark.parametrize("tilt", [5e-5, 3e-4, 1.5e-3])
def test_a_linear_bed_is_the_librarys_kinked_tilt_law(tilt):
    case = case_for(7)
    f = protocol_loads(case)
    library = ContactLaw("tripp", 2e-3, (Misalignment(tilt),)).stiffness_n_per_m(case, f)
    np.testing.assert_allclose(tilt_on_stiffening_bed(tilt, 1.0, INNER)(case, f), library, rtol=1e-6)


@pytest.mark.parametrize("a", [0.55, 0.7, 0.85])
def test_a_stiffening_bed_has_another_partial_contact_exponent_and_no_kink(a):
    case = case_for(7)
    f = np.array([1.0, 2.0])  # far from full contact at a 5 mrad tilt
    k = tilt_on_stiffening_bed(5e-3, a, lambda c, load: np.full(load.size, 1e9))(case, f)
    assert np.log(k[1] / k[0]) / np.log(2.0) == pytest.approx(a / (1.0 + a), rel=1e-4)  # the library: ½
    # and it approaches full contact slowly (load spread unevenly along a bed that stiffens): no kink
    loads = protocol_loads(case)
    ratio = tilt_on_stiffening_bed(3e-4, a, INNER)(case, loads) / INNER(case, loads)
    assert np.all(np.diff(ratio) > 0) and ratio[-1] < 1.0
