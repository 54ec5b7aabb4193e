"""Synthetic stiffness tables: a campaign's loads and repetitions on catalogue rollers, with chosen truth and noise.

Used to prove the workflow on data whose hidden effect is known (tests, ``bench/discrepancy_eval.py``) and to
ask before a campaign whether an effect of a given size would be found. Loads follow the paper's protocol:
from the preload (~38 N) to 30 % of C0 in geometric steps; noise is log-normal, larger at low load.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

from labctl.physics.catalogue import roller
from labctl.physics.effects import ContactCase
from labctl.physics.materials import BEARING_STEEL, material
from labctl.physics.rating import static_load_rating_n
from labctl.stiffness_table import StiffnessPoint

PRELOAD_N = 38.0
MAX_C0_FRACTION = 0.3
Truth = Callable[[ContactCase, np.ndarray], np.ndarray]
"""Stiffness (N/m) of a contact case at loads (N): the hidden world."""


@dataclass(frozen=True)
class NoiseModel:
    """Relative scatter of one measured point: ``low`` at the preload falling log-linearly to ``high`` at the
    top load (the paper: < 5 % at low load, < 1 % at high load); load readings scatter by ``load_rel``."""

    low: float = 0.02
    high: float = 0.02
    load_rel: float = 0.003

    def sigma(self, load_n: np.ndarray, top_n: float) -> np.ndarray:
        u = np.clip(np.log(load_n / PRELOAD_N) / np.log(max(top_n / PRELOAD_N, 1.0 + 1e-9)), 0.0, 1.0)
        return np.exp((1.0 - u) * np.log(self.low) + u * np.log(self.high))


def case_for(type_id: int, rail_ra_m: float = 0.2e-6) -> ContactCase:
    """A catalogue roller between bearing-steel rails."""
    return ContactCase(roller(type_id), material(BEARING_STEEL), rail_ra_m)


def protocol_loads(case: ContactCase, steps: int = 11) -> np.ndarray:
    """Load steps per roller: preload to 30 % of C0 (total length), geometric."""
    top = MAX_C0_FRACTION * static_load_rating_n(case.roller, case.rail)
    return np.geomspace(PRELOAD_N, top, steps)


def synthesize(truth: Truth, types: Iterable[int] = range(1, 8), *, rail_ra_m: float = 0.2e-6,
               repetitions: int = 3, steps: int = 11, noise: NoiseModel | None = None,
               seed: int | None = 0, seating_rel: float = 0.0) -> list[StiffnessPoint]:
    """Points of a simulated campaign: each roller type, each repetition, each load step, with noise.

    ``seating_rel``: σ of a load-independent factor shared by all points of one seating (repetition), as a
    roller reseated on another contact spot gives.
    """
    rng = np.random.default_rng(seed)
    noise = noise or NoiseModel()
    points: list[StiffnessPoint] = []
    for t in types:
        case = case_for(t, rail_ra_m)
        nominal = protocol_loads(case, steps)
        r = case.roller
        for rep in range(1, repetitions + 1):
            loads = nominal * np.exp(noise.load_rel * rng.standard_normal(steps))
            k = truth(case, loads) * np.exp(noise.sigma(loads, nominal[-1]) * rng.standard_normal(steps))
            if seating_rel > 0:
                k = k * np.exp(seating_rel * rng.standard_normal())
            points.extend(
                StiffnessPoint(r.diameter_m, r.contact_length_m, rail_ra_m, float(f), float(kk), roller_type=t,
                               roller_length_m=r.total_length_m, material=r.material.name, repetition=rep)
                for f, kk in zip(loads, k, strict=True)
            )
    return points
