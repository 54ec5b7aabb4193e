"""Rig eigen-analysis against closed forms (Eq. 4 and the tilt pendulum), unequal springs, and the inverse."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from labctl.errors import ModelDomainError
from labctl.physics import load_rig, rig_modes, roller_stiffness_from_bounce
from labctl.physics.rig_config import Disc

RIG = load_rig()


def free_rig():
    """The paper rig with a negligible support, where Eq. 4 holds exactly."""
    return dataclasses.replace(RIG, support_stiffness_n_per_m=1e-6)


def eq4_bounce_hz(k, m, k_setup):
    k_total = 1.0 / (1.0 / (3 * k) + 1.0 / k_setup)
    return math.sqrt(2 * k_total / m) / (2 * math.pi)


@pytest.mark.parametrize("k", [1e7, 4.65e7, 2e8])
def test_equal_springs_bounce_matches_eq4_and_tilt_closed_form(k):
    rig = free_rig()
    modes = rig_modes(rig, k)
    assert modes.bounce_hz == pytest.approx(eq4_bounce_hz(k, rig.upper.mass_kg, rig.setup_stiffness_n_per_m), rel=1e-9)
    k_path = 1.0 / (1.0 / k + 3.0 / rig.setup_stiffness_n_per_m)
    tilt = math.sqrt(1.5 * k_path * rig.contact_radius_m**2 * 2 / rig.upper.inertia_kg_m2) / (2 * math.pi)
    assert modes.tilt_hz == pytest.approx((tilt, tilt), rel=1e-9)


def test_paper_rig_gives_fig6_frequencies():
    modes = rig_modes(RIG, 4.65e7)
    assert modes.bounce_hz == pytest.approx(745, abs=4)
    assert modes.tilt_hz[0] == pytest.approx(581, abs=6) and modes.tilt_hz[1] == pytest.approx(581, abs=6)
    assert max(modes.frequencies_hz[list(modes.support)]) < 60  # rigid-body modes on the rubber tube


def test_bounce_shape_top_in_phase_bottom_opposite_and_tilt_top_sums_to_zero():
    modes = rig_modes(RIG, 4.65e7)
    b = modes.sensor_shapes(modes.bounce)
    tops = np.array([b["A1Z"], b["A2Z"], b["A3Z"]])
    assert np.all(np.sign(tops) == np.sign(tops[0])) and np.sign(b["A4Z"]) == -np.sign(tops[0])
    for i in modes.tilt:
        t = modes.sensor_shapes(i)
        top = np.array([t["A1Z"], t["A2Z"], t["A3Z"]])
        assert abs(top.sum()) < 1e-6 * np.abs(top).max()
        assert abs(t["A4Z"]) < 1e-6 * np.abs(top).max()


def test_unequal_springs_split_the_tilt_pair():
    equal = rig_modes(RIG, 4.65e7).tilt_hz
    split = rig_modes(RIG, [4.0e7, 4.65e7, 5.3e7]).tilt_hz
    assert equal[1] - equal[0] < 1e-6
    assert split[1] - split[0] > 10.0


def test_unequal_disc_masses_still_follow_two_body_formula():
    rig = dataclasses.replace(free_rig(), lower=Disc(20.0, 0.09, 0.03))
    k = 5e7
    k_total = 1.0 / (1.0 / (3 * k) + 1.0 / rig.setup_stiffness_n_per_m)
    expected = math.sqrt(k_total * (1 / rig.upper.mass_kg + 1 / 20.0)) / (2 * math.pi)
    assert rig_modes(rig, k).bounce_hz == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize("k", [5e6, 4.65e7, 3e8])
def test_frequency_stiffness_round_trip(k):
    f = rig_modes(RIG, k).bounce_hz
    assert roller_stiffness_from_bounce(RIG, f) == pytest.approx(k, rel=1e-8)


def test_inverse_matches_eq4_at_745hz():
    assert roller_stiffness_from_bounce(RIG, 745.0) == pytest.approx(4.65e7, rel=1e-2)


def test_inverse_refuses_impossible_frequency():
    with pytest.raises(ModelDomainError, match="outside"):
        roller_stiffness_from_bounce(RIG, 5000.0)
    with pytest.raises(ModelDomainError):
        roller_stiffness_from_bounce(RIG, -3.0)


def test_preload_is_upper_disc_weight_shared_by_three_rollers():
    assert RIG.preload_per_roller_n == pytest.approx(38.0, rel=0.02)


def test_bounce_sensitivity_matches_finite_differences_of_the_rig_model():
    from labctl.physics.rig import bounce_sensitivity

    k, h = 4.65e7, 1e-6
    sens = bounce_sensitivity(RIG, k)
    f0 = rig_modes(RIG, k).bounce_hz

    def scaled(d):
        return dataclasses.replace(d, mass_kg=d.mass_kg * (1 + h), inertia_kg_m2=d.inertia_kg_m2 * (1 + h))

    heavier = dataclasses.replace(RIG, upper=scaled(RIG.upper), lower=scaled(RIG.lower))
    assert sens.per_disc_mass == pytest.approx((rig_modes(heavier, k).bounce_hz - f0) / (RIG.upper.mass_kg * h),
                                               rel=1e-4)
    stiffer = RIG.with_setup_stiffness(RIG.setup_stiffness_n_per_m * (1 + h))
    assert sens.per_setup_stiffness == pytest.approx(
        (rig_modes(stiffer, k).bounce_hz - f0) / (RIG.setup_stiffness_n_per_m * h), rel=1e-3)
    assert sens.per_roller_stiffness == pytest.approx((rig_modes(RIG, k * (1 + h)).bounce_hz - f0) / (k * h), rel=1e-3)
    assert sens.per_disc_mass < 0 < sens.per_roller_stiffness
