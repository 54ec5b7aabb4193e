"""All contact cases of a dataset evaluated as one stack of per-point cases give what each case gives alone, to the
last bit but for NumPy's vectorised powers (one ulp): every model term and measurement-side term, on roller types
of another material and rail roughness."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from labctl.discrepancy.data import build_dataset
from labctl.discrepancy.measurement import LoadGain, LoadOffset, ModulusScale
from labctl.discrepancy.model import predict_ln
from labctl.discrepancy.synthetic import NoiseModel, synthesize
from labctl.physics import ContactLaw, EndEffects, MaterialHardness, Misalignment, SetupCompliance, SurfaceRoughness

LAWS = [
    ContactLaw("tripp", 2.2e-3, (SurfaceRoughness(1.3), EndEffects(0.2e-3), MaterialHardness(0.6, 0.2),
                                 Misalignment(4e-4, transition=0.2), SetupCompliance(0.7))),
    ContactLaw("tripp", 1.1e-3, (Misalignment(2e-3),)),
    ContactLaw("palmgren"),
    ContactLaw("fit-ra0.03", effects=(SurfaceRoughness(0.5),)),
]
CHAINS = [(), (LoadGain(1.1),), (LoadOffset(45.0),), (ModulusScale(0.8), LoadOffset(-10.0))]


def mixed_points():
    """Types 1-7 of bearing steel on Ra 0.2 µm rails; types 2 and 5 of silicon nitride (another E, ν and hardness)
    on Ra 0.03 µm rails of another steel."""
    truth = ContactLaw("tripp").stiffness_n_per_m
    pts = synthesize(truth, noise=NoiseModel(0.02, 0.01), seed=3)
    other = synthesize(truth, types=(2, 5), rail_ra_m=0.03e-6, noise=NoiseModel(0.02, 0.01), seed=4)
    return pts + [replace(p, material="Si3N4", rail_material="1.4034") for p in other]


@pytest.mark.parametrize("chain", CHAINS, ids=["none", "gain", "offset", "modulus+offset"])
@pytest.mark.parametrize("law", LAWS, ids=["tripp+all", "tilt", "palmgren", "fit+roughness"])
def test_the_stack_equals_each_case_alone_to_the_last_bit(law, chain):
    data = build_dataset(mixed_points())
    assert len(data.cases) >= 9
    per_case = []
    for c in data.cases:
        case, load = c.case, c.load_n
        for term in chain:
            case, load = term.transform(case, load)
        with np.errstate(invalid="ignore"):
            value = np.log(law.stiffness_n_per_m(case, np.where(load > 0, load, 1.0)))
        per_case.append(np.where(load > 0, value, np.nan))
    with np.errstate(invalid="ignore"):
        stacked = predict_ln(data, law, chain)
    alone = np.concatenate(per_case)
    np.testing.assert_array_equal(np.isnan(stacked), np.isnan(alone))
    np.testing.assert_allclose(stacked, alone, rtol=4e-16, atol=0)  # ≤ 2 ulp: NumPy's array ** vs a float's
    if chain and isinstance(chain[-1], LoadOffset) and chain[-1].offset_n > 40:
        assert np.isnan(stacked).any()  # the offset exceeds the lowest recorded loads: no model there


def test_a_stacked_material_is_still_checked():
    from labctl.errors import InputError
    from labctl.physics.materials import Material

    with pytest.raises(InputError, match="Young's modulus"):
        Material("stacked", np.array([2e11, -1.0]), np.array([0.3, 0.3]), np.array([60.0, 60.0]))


def test_a_load_below_an_empirical_fits_range_is_a_domain_error_naming_the_point():
    """Eq. 5 on the stack, with a load offset that puts the lowest loads below its range: the model's own domain
    error (which the fits catch), naming the first such point's load and contact length, not a TypeError."""
    from labctl.physics.contact import ModelDomainError

    data = build_dataset(mixed_points())
    with pytest.raises(ModelDomainError, match=r"valid only for F/L_we > .* mm; got .* N"):
        predict_ln(data, ContactLaw("fit-ra0.2"), (LoadOffset(30.0),))
