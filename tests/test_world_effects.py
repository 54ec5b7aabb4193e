"""Each shipped world's hidden effect shows the signature docs/simulator.md documents for it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from drivers import TriggerSpec
from drivers.sim import twin_of
from labctl.backends import make_rig
from labctl.physics import (
    ContactCase,
    HertzBallContact,
    Roller,
    TrippContact,
    load_rig,
    material,
    rig_modes,
    roller,
    roller_stiffness_from_bounce,
    static_load_rating_n,
)
from labctl.physics.world import ball, load_world

STEEL = material("1.3505")
RIG = load_rig()


def ratio_to_tripp(world: str, r: Roller, loads, rail_ra_m: float = 0.2e-6) -> np.ndarray:
    """World stiffness over plain Tripp at the world's depth: what the hidden effect does."""
    law = load_world(world).law
    case = ContactCase(r, STEEL, rail_ra_m)
    return law.stiffness_n_per_m(case, loads) / TrippContact(r, STEEL, law.depth_m).stiffness_n_per_m(loads)


def load_range(r: Roller, n: int = 6) -> np.ndarray:
    return np.geomspace(RIG.preload_per_roller_n, 0.3 * static_load_rating_n(r, STEEL), n)


def test_surface_roughness_bites_at_low_load_grows_with_ra_and_ignores_diameter():
    r = roller(1)
    loads = load_range(r)
    ratio = ratio_to_tripp("surface_roughness", r, loads)
    assert np.all(np.diff(ratio) > 0) and ratio[0] < 0.6 and ratio[-1] > 0.85
    rough = ratio_to_tripp("surface_roughness", r, loads, rail_ra_m=0.8e-6)
    smooth = ratio_to_tripp("surface_roughness", r, loads, rail_ra_m=0.03e-6)
    assert np.all(rough < ratio) and np.all(smooth > ratio) and smooth[0] > 0.75
    # the asperity compliance added at one load is the same for a thin and a thick roller of one length
    added = []
    for d_m in (3e-3, 6e-3):
        thin = dataclasses.replace(r, diameter_m=d_m)
        law, case = load_world("surface_roughness").law, ContactCase(thin, STEEL, 0.2e-6)
        base = TrippContact(thin, STEEL, law.depth_m).stiffness_n_per_m(100.0)
        added.append(1 / law.stiffness_n_per_m(case, 100.0) - 1 / base)
    assert added[0] == pytest.approx(added[1], rel=1e-9)


def test_end_effects_raise_stiffness_per_length_more_for_short_rollers():
    short, long_ = roller(2), roller(4)  # L_we 1.1 mm and 8.3 mm
    gain_short = ratio_to_tripp("end_effects", short, load_range(short))
    gain_long = ratio_to_tripp("end_effects", long_, load_range(long_))
    assert np.ptp(gain_short) < 1e-9 and np.ptp(gain_long) < 1e-9  # the same at every load
    assert gain_short[0] == pytest.approx(1 + 2 * 0.1 / 1.104, rel=1e-6)
    assert gain_short[0] - 1 > 5 * (gain_long[0] - 1) > 0


def test_material_hardness_stiffens_soft_rollers_at_high_load_on_rough_rails():
    hard, soft = roller(1), roller(9)  # bearing steel HRC 60, stainless HRC 54; same geometry
    loads = load_range(hard)
    g_hard, g_soft = ratio_to_tripp("material_hardness", hard, loads), ratio_to_tripp("material_hardness", soft, loads)
    assert g_hard[0] == 1.0 and g_soft[0] == 1.0  # below the yield threshold nothing changes
    assert np.all(np.diff(g_soft) >= 0) and g_soft[-1] > 1.1
    assert g_soft[-1] > g_hard[-1] > 1.0
    g_smooth = ratio_to_tripp("material_hardness", soft, loads, rail_ra_m=0.03e-6)
    assert g_smooth[-1] - 1 < 0.5 * (g_soft[-1] - 1)


def test_misalignment_softens_at_low_load_and_long_rollers_far_more():
    short, long_ = roller(1), roller(4)
    loss_short = ratio_to_tripp("misalignment", short, load_range(short))
    loss_long = ratio_to_tripp("misalignment", long_, load_range(long_))
    assert loss_short[0] < 1.0 and loss_short[-1] == 1.0  # the gap closes under load
    assert loss_long[0] < 0.5 * loss_short[0] and np.all(np.diff(loss_long) >= 0)
    assert loss_long[-1] == 1.0
    # the tilt is redrawn per seating: the low-load stiffness scatters, the fully closed contact does not
    spec = load_world("misalignment").specimen(ContactCase(long_, STEEL, 0.2e-6))
    rng = np.random.default_rng(0)
    seats = [spec.seat(rng) for _ in range(20)]
    low = [s.stiffness_n_per_m(100.0) for s in seats]
    high = [s.stiffness_n_per_m(4000.0) for s in seats]
    assert np.std(low) / np.mean(low) > 0.03 > 0.005 > np.std(high) / np.mean(high)


def test_setup_compliance_hides_in_the_dynamics_and_its_error_grows_with_k():
    case = ContactCase(roller(4), STEEL, 0.2e-6)
    rig = make_rig("sim", case=case, world="setup_compliance", seed=1)
    twin = twin_of(rig)
    errors = []
    for load in (60.0, 1500.0):
        twin.set_load_per_roller(load)
        truth = twin.truth()
        k_true = np.mean(truth["roller_stiffness_n_per_m"])
        nominal = rig_modes(RIG, truth["roller_stiffness_n_per_m"]).bounce_hz
        assert truth["bounce_hz"] > nominal  # the rig is really stiffer than its file says
        k_reported = roller_stiffness_from_bounce(RIG, truth["bounce_hz"])  # processing assumes nominal K_setup
        errors.append(k_reported / k_true - 1)
    assert 0 < errors[0] < errors[1]
    assert errors[1] > 0.03


def test_balls_follow_hertz_with_a_third_power_law():
    b = ball(6e-3, STEEL)
    case = ContactCase(b, STEEL, 0.2e-6)
    world = load_world("balls")
    loads = np.array([40.0, 400.0])
    k = world.law.stiffness_n_per_m(case, loads)
    np.testing.assert_allclose(k, HertzBallContact(6e-3, STEEL, STEEL).stiffness_n_per_m(loads), rtol=1e-12)
    assert np.log(k[1] / k[0]) / np.log(10) == pytest.approx(1 / 3)
    rng = np.random.default_rng(1)
    seated = [world.specimen(case).seat(rng).stiffness_n_per_m(100.0) for _ in range(40)]
    assert 0.001 < np.std(seated) / np.mean(seated) < 0.03  # reseating scatters, and stays below the paper's 3 %


def test_null_worlds_are_plain_tripp():
    r = roller(3)
    loads = load_range(r)
    np.testing.assert_allclose(ratio_to_tripp("tripp_only", r, loads), 1.0, rtol=1e-12)
    np.testing.assert_allclose(ratio_to_tripp("ideal", r, loads), 1.0, rtol=1e-12)
    rig = make_rig("sim", case=ContactCase(r, STEEL, 0.2e-6), world="ideal", seed=3)
    twin = twin_of(rig)
    k = twin.roller_stiffness_n_per_m()
    assert k[0] == k[1] == k[2]  # no seating scatter
    rig.daq.configure(20_480, 2048)
    rig.daq.arm(TriggerSpec(pretrigger_samples=200))
    rig.hammer.strike()
    rec = rig.daq.acquire(1.0)
    assert np.max(np.abs(rec.force_n[:150])) < 0.01  # no noise: quantisation only
