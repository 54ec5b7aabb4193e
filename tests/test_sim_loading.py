"""How the simulated rig is loaded as the paper loaded it: the C0 convention and the half-turn grid reach 440 N."""

from __future__ import annotations

import pytest

from labctl.engine.plan import plan_steps
from labctl.physics import effective_modulus, load_rig, material, roller, static_load_rating_n
from labctl.protocol import load_protocol

STEEL = material("1.3505")


def test_c0_rates_the_raceway_whatever_the_roller_material():
    c0 = {t: static_load_rating_n(roller(t), STEEL) for t in (1, 5, 8, 9)}
    assert c0[9] == pytest.approx(c0[1])  # stainless type 9 has type 1's geometry (D 3, L_r 2.2 mm)
    assert c0[8] == pytest.approx(c0[5])  # Si3N4 type 8 has type 5's D and L_r
    # with the roller's own E* the ratings would differ by the moduli (Si3N4 stiffer → a lower C0)
    own = static_load_rating_n(roller(8), STEEL) * effective_modulus(STEEL, STEEL) / effective_modulus(
        roller(8).material, STEEL)
    assert own < 0.9 * c0[8]
    assert 440.0 / c0[1] == pytest.approx(0.304, abs=0.001)  # the paper's top load: 30.4 % of C0 (L_r)


def test_the_shipped_protocol_reaches_the_papers_440_n_for_type_1_in_half_turns():
    proto = load_protocol("protocols/roller_stiffness.toml")
    spec, rig = proto.specimens[0], load_rig()
    plan = plan_steps(proto, spec, rig)
    assert plan.step_angle_deg == 180.0 and plan.cap_n >= 440.0
    per_step = rig.load_per_knob_degree_n * plan.step_angle_deg
    top = rig.preload_per_roller_n + (plan.steps_estimate - 1) * per_step
    assert 440.0 <= top <= plan.cap_n  # the tenth half turn: the paper's Fig. 7 load
