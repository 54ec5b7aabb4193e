"""The twin's displacement sensor: what a capacitive or eddy-current probe between the discs reads.

It reads the true closing of the discs since the preload — each roller path's deflection, i.e. the contact in
series with its share of the setup compliance (the rig's own deflection, which the static method must remove as
the rig model does) — averaged over the three rollers (the probe sits at the disc centre), plus the sensor's
thermal drift (a rate drawn anew each time the rollers are re-seated, since the disc was lifted and handled),
its white noise per sample, and the ADC's resolution; a reading is the DC average of the samples of one window.
The path stiffness comes in as a function (``labctl.physics.rig.roller_path_stiffness``): drivers import no
labctl.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drivers.errors import DeviceError
from drivers.sim.instruments import _SimInstrument
from drivers.sim.twin import RigTwin

PathStiffness = Callable[[np.ndarray, float], np.ndarray]
"""(roller stiffnesses, K_setup) → each roller path's stiffness (roller in series with 3/K_setup)."""

_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(48)


@dataclass(frozen=True)
class DisplacementSettings:
    """The simulated probe and its DAQ channel (SI). Defaults: an LVDT of ±1 mm whose conditioner gives 100 µm/V
    into a 16-bit ±10 V input (one count 30.5 nm), 0.1 µm rms noise per sample at 1 kS/s (the conditioner and the
    rig's floor vibration), 0.1 s windows, and a thermal drift of 10 nm/min (1 σ of the rate) in a lab held to a
    fraction of a kelvin."""

    noise_m: float = 0.1e-6
    sample_rate_hz: float = 1000.0
    window_s: float = 0.1
    resolution_m: float = 30.52e-9
    drift_std_m_per_s: float = 10e-9 / 60.0
    range_m: float = 2e-3
    standoff_m: float = 1e-3  # the reading at the preload (the probe's core is set mid-stroke)

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"displacement sensor setting {name} = {value!r}: expected a finite number >= 0")
        if not (self.sample_rate_hz > 0 and self.window_s > 0):
            raise ValueError("displacement sensor: sample_rate_hz and window_s must be > 0")


class SimDisplacementSensor(_SimInstrument):
    """The probe of ``twin``: ``read`` returns the window's DC average in metres and lets the window pass."""

    def __init__(self, twin: RigTwin, path_stiffness: PathStiffness, settings: DisplacementSettings | None = None,
                 name: str = "sim-displacement") -> None:
        super().__init__(twin, name)
        self.settings = settings or DisplacementSettings()
        self._path = path_stiffness
        self._rng = np.random.default_rng([twin.seed, 0xD15])
        self._seating = -1
        self._drift_rate = 0.0
        self._drift_m = 0.0
        self._drift_since_s = 0.0

    def true_closing_m(self) -> float:
        """The discs' closing since the preload now: ∫ mean over rollers of 1/k_path(p) dp from the preload."""
        twin = self.twin
        p0, p = twin.preload_n, twin.load_per_roller_n()
        if p <= p0:
            return 0.0
        loads = p0 + (p - p0) * (_NODES + 1.0) / 2.0
        k = np.array([r.stiffness_curve_n_per_m(loads) for r in twin.rollers])
        setup = float(twin.rig.setup_stiffness_n_per_m)
        compliance = np.mean(1.0 / self._path(k, setup), axis=0)
        return float((p - p0) / 2.0 * np.dot(_WEIGHTS, compliance))

    def _drift(self) -> float:
        if self._seating != self.twin.rotations:  # the disc was lifted: a new thermal state
            self._drift_m += self._drift_rate * (self.twin.time_s - self._drift_since_s)
            self._seating = self.twin.rotations
            self._drift_rate = float(self._rng.normal(0.0, self.settings.drift_std_m_per_s))
            self._drift_since_s = self.twin.time_s
        return self._drift_m + self._drift_rate * (self.twin.time_s - self._drift_since_s)

    def read(self) -> float:
        self._check("read")
        s = self.settings
        n = max(1, round(s.window_s * s.sample_rate_hz))
        self.twin.time_s += n / s.sample_rate_hz
        value = s.standoff_m + self.true_closing_m() + self._drift()
        if not 0.0 <= value <= s.range_m:
            raise DeviceError(self.name, "read", f"{value * 1e6:.1f} µm is outside the probe's range "
                              f"0..{s.range_m * 1e6:g} µm: reset the probe's gap")
        samples = value + self._rng.normal(0.0, s.noise_m, n)
        if s.resolution_m > 0:
            samples = np.round(samples / s.resolution_m) * s.resolution_m
        return float(np.mean(samples))
