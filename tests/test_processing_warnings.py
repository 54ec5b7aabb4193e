"""Warnings on the digital twin are material: none at the paper's 440 N with its usual hammer; "hit softer"
where the blow truly moves the stiffness (38 N per roller, 250 N blows), and not once the hammer is lighter —
as the twin's technician, matching the blow to the load, hits by default."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from drivers.sim import twin_of
from labctl.backends import make_rig
from labctl.cli.simulate import strike_series
from labctl.physics import ContactCase, load_rig, material, roller
from labctl.physics.materials import BEARING_STEEL
from labctl.processing import identify

RIG = load_rig()


def step(load_n: float, seed: int, hammer_n: float | None = None):
    rig = make_rig("sim", case=ContactCase(roller(1), material(BEARING_STEEL), 0.2e-6), seed=seed)
    twin = twin_of(rig)
    if hammer_n is not None:
        twin.settings = replace(twin.settings, peak_force_n=hammer_n, peak_force_per_load=0.0)
    twin.set_load_per_roller(load_n)
    fs, force, accel, channels = strike_series(rig, 3)
    return identify(force, accel, fs, channels, RIG), twin.truth()


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_twin_at_440_n_warns_nothing(seed):
    """The blow moves the bounce ~0.3 Hz at 440 N (0.1 % in k, below the stated σ): no "hit softer", and the
    per-roller stiffnesses are solved."""
    r, truth = step(440.0, seed)
    assert r.warnings == [], r.warnings
    assert r.blow_effect is not None and not r.blow_effect["material"]
    k, std = np.array(r.roller_stiffnesses_n_per_m), np.array(r.roller_stiffnesses_fit_std_n_per_m)
    assert np.all(np.abs(k - np.array(truth["roller_stiffness_n_per_m"])) <= 3 * std)


def test_a_hammer_too_hard_for_the_preload_is_named_and_a_lighter_one_is_not():
    """38 N per roller under 250 N blows: the reported k is ~2 % below the twin's truth; the warning says by how
    much and to hit softer. At a 60 N hammer level the same step is within 0.3 % and says nothing of the hammer."""
    r, truth = step(38.0, 1, hammer_n=250.0)
    k_true = float(np.mean(truth["roller_stiffness_n_per_m"]))
    assert r.roller_stiffness_n_per_m < 0.99 * k_true
    warning = next(w for w in r.warnings if "hit softer" in w)
    assert f"{100 * r.blow_effect['effect_rel']:.2f} %" in warning
    soft, truth = step(38.0, 1, hammer_n=60.0)
    assert not any("hit softer" in w for w in soft.warnings), soft.warnings
    assert soft.roller_stiffness_n_per_m == pytest.approx(float(np.mean(truth["roller_stiffness_n_per_m"])), rel=3e-3)


@pytest.mark.parametrize("load_n, level_n", [(38.0, 60.0), (150.0, 150.0), (440.0, 250.0)])
def test_the_twins_technician_matches_the_blow_to_the_load(load_n, level_n):
    """By default the twin's hammer level is 1.0 × the load per roller within the hammer's usable 60-250 N (a
    light blow at a light load): at 38 N the blows are light enough that nothing says "hit softer" and k is
    within 0.3 % of the truth (at a fixed 250 N it is ~2 % low, the test above)."""
    rig = make_rig("sim", case=ContactCase(roller(1), material(BEARING_STEEL), 0.2e-6), seed=1)
    twin = twin_of(rig)
    twin.set_load_per_roller(load_n)
    assert twin.hammer_level_n() == pytest.approx(level_n, rel=1e-3)
    if load_n == 38.0:
        fs, force, accel, channels = strike_series(rig, 3)
        r, truth = identify(force, accel, fs, channels, RIG), twin.truth()
        assert not any("hit softer" in w for w in r.warnings), r.warnings
        assert r.roller_stiffness_n_per_m == pytest.approx(float(np.mean(truth["roller_stiffness_n_per_m"])),
                                                           rel=3e-3)
