"""What the simulated rig needs from the physics, as small Protocols, and its instrument settings.

``drivers`` never imports ``labctl``: the backend factory passes the rig description, the seated-roller model
and the modes function in as objects that satisfy these Protocols (``labctl.physics`` provides them).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

STANDARD_GRAVITY = 9.80665


class LoadingLike(Protocol):
    """Star knobs on threaded rods pressing compression springs (rig file ``[loading]``)."""

    rods: int
    thread_pitch_m: float
    spring_rate_n_per_m: float


class FlexibleModeLike(Protocol):
    """A disc bending mode: frequency, damping, modal mass, relative amplitude at the hammer and per channel."""

    frequency_hz: float
    damping_ratio: float
    modal_mass_kg: float
    hammer: float
    shape: Mapping[str, float]


class RigLike(Protocol):
    """The rig description the twin reads (``labctl.physics.rig_config.RigConfig`` satisfies it)."""

    name: str
    loading: LoadingLike
    hammer_xy_m: tuple[float, float]
    flexible_modes: Sequence[FlexibleModeLike]
    setup_stiffness_n_per_m: float  # K_setup: the rig's own deflection, which the displacement sensor reads too

    @property
    def channels(self) -> tuple[str, ...]: ...

    @property
    def preload_per_roller_n(self) -> float: ...

    @property
    def roller_count(self) -> int: ...

    @property
    def load_per_knob_degree_n(self) -> float: ...


class ModesLike(Protocol):
    """Rigid-body modes of the rig for one set of roller stiffnesses (``labctl.physics.rig.RigModes``)."""

    frequencies_hz: np.ndarray
    damping_ratios: np.ndarray

    @property
    def bounce_hz(self) -> float: ...

    @property
    def tilt_hz(self) -> tuple[float, float]: ...

    def sensor_shapes(self, mode: int) -> dict[str, float]: ...

    def vertical_at(self, disc: str, x_m: float, y_m: float, mode: int) -> float: ...


ModesFunction = Callable[[RigLike, Sequence[float]], ModesLike]
"""Eigen-analysis of the rig for three roller stiffnesses (``labctl.physics.rig.rig_modes``)."""


class SeatedRoller(Protocol):
    """One roller as it sits between its rails since it was last placed: its stiffness at a load."""

    def stiffness_n_per_m(self, load_n: float) -> float: ...

    def stiffness_curve_n_per_m(self, loads_n: np.ndarray) -> np.ndarray:
        """The stiffness at many loads in one evaluation (the displacement probe integrates the compliance)."""
        ...


SwingStiffnessFunction = Callable[[Callable[[float], float], float, float, float], float]
"""(k(F), load, force swing ΔF, scale) → the contact's effective stiffness while its force swings by ±ΔF about
the load (``labctl.physics.contact.swing_stiffness_n_per_m``)."""


class Specimen(Protocol):
    """The rollers under test in the hidden world: each placement draws a new seating (contact spot)."""

    def seat(self, rng: np.random.Generator) -> SeatedRoller: ...

    def on_burr(self, seated: SeatedRoller, gap_m: float) -> SeatedRoller:
        """``seated`` with a burr or particle of height ``gap_m`` under it (an unequal-seating fault)."""
        ...


@dataclass(frozen=True)
class SimSettings:
    """Transducers, hammer and noise of the simulated rig (SI); a world file may override any field.

    Defaults: PCB 086D05 hammer (0.23 mV/N, ±22.24 kN) with a medium tip, PCB 356A16 accelerometers
    (100 mV/g, ±50 g), a 24-bit ±5 V acquisition front end, a load cell with 0.3 N noise.
    """

    force_sensitivity_v_per_n: float = 0.23e-3
    force_range_n: float = 22_240.0
    accel_sensitivity_v_per_m_per_s2: float = 0.100 / STANDARD_GRAVITY
    accel_range_m_per_s2: float = 50.0 * STANDARD_GRAVITY
    adc_bits: int = 24
    force_noise_n: float = 0.05
    accel_noise_m_per_s2: float = 0.004
    max_sample_rate_hz: float = 102_400.0
    base_clock_hz: float = 0.0  # > 0: the DAQ sets base_clock / integer, like an NI 9234 (51.2 kS/s ÷ n)
    pulse_width_min_s: float = 0.25e-3
    pulse_width_max_s: float = 0.45e-3
    peak_force_n: float = 250.0  # the hammer's mean peak force (the cap when it follows the load)
    peak_force_per_load: float = 1.0  # > 0: the technician matches the blow to the load, mean peak = ratio × load
    peak_force_min_n: float = 60.0  # ... per roller, within [peak_force_min_n, peak_force_n]; 0: always peak_force_n
    peak_force_rel: float = 0.2
    impact_scatter_m: float = 2e-3
    load_cell_noise_n: float = 0.3
    load_cell_settle_reads: int = 2
    load_cell_read_s: float = 0.1
    load_creep_n_per_s: float = 0.0
    stable_rate_n_per_s: float = 0.5
    knob_turn_s_per_deg: float = 0.01
    knob_slack_deg: float = 0.0  # after re-seating, the nuts turn up to this far (uniform) before the springs bite
    spring_imperfection: float = 0.0  # > 0: real spring stacks (drivers.sim.springs) at this scale; 0: linear nominal
    spring_stack_seed: int = 1  # which springs the rig has: the same in every run of a world, whatever its seed
    contact_nonlinearity: float = 1.0  # 1: a blow's force swing shifts the contact stiffness (first order); 0: off

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not np.isfinite(value) or value < 0 and name != "load_creep_n_per_s":
                raise ValueError(f"simulator setting {name} = {value!r}: expected a finite number >= 0")
        if not 0 < self.pulse_width_min_s <= self.pulse_width_max_s:
            raise ValueError(
                f"simulator settings: pulse width range {self.pulse_width_min_s!r}..{self.pulse_width_max_s!r} s "
                "must be positive and increasing"
            )
        if self.peak_force_per_load > 0 and not self.peak_force_min_n <= self.peak_force_n:
            raise ValueError(f"simulator settings: peak_force_min_n {self.peak_force_min_n!r} N above peak_force_n "
                             f"{self.peak_force_n!r} N: the hammer's usable range must be increasing")
