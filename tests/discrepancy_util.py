"""Shared pieces of the discrepancy tests: a hidden-effect world as a stiffness law, the names a result gives."""

from __future__ import annotations

from labctl.discrepancy.synthetic import NoiseModel
from labctl.physics import ContactLaw

DEPTH_M = 2e-3
GENERATOR_NOISE = NoiseModel(low=0.02, high=0.02 / 3)
"""The independent generator's noise: 2 % at the preload, a third of it at the top of the load range."""
NOISE = NoiseModel(low=0.03, high=0.01)
"""The workflow tests' noise: 3 % per point at the preload, 1 % near 30 % of C0 (the paper's spread)."""


def world(*effects, depth_m=DEPTH_M):
    """Tripp at ``depth_m`` with ``effects`` applied in order, as a (case, load) → stiffness law."""
    return ContactLaw("tripp", depth_m, tuple(effects)).stiffness_n_per_m


def names(result):
    return [s.name for s in result.steps]
