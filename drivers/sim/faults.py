"""Faults a technician meets on the real rig, generated inside the simulated instruments (rates and sizes per world).

Every fault acts where it would on hardware, so the engine and the processing meet it through the ordinary
interfaces: a second hammer pulse in the force record, a channel at its range, a channel that records only
noise, mains hum on the accelerometers, a load that creeps after a knob turn, a load cell that does not answer
or answers garbage, one roller seated on a burr. All rates are probabilities per event (blow, record, read,
knob turn, seating); all draws come from the twin's own fault stream, so a world without faults is unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np


@dataclass(frozen=True)
class FaultSettings:
    """Rates (probability per event) and sizes (SI) of the simulated rig's faults; all zero: a fault-free rig."""

    double_hit_rate: float = 0.0  # per blow: the hammer bounces back, a second pulse 20-60 % as strong at 1-3 ms
    late_double_hit_rate: float = 0.0  # per blow: a small late second hit, 1-5 % as strong at +2 to +10 ms
    overload_rate: float = 0.0  # per blow: one channel (force or an accelerometer) driven past its range
    intermittent_channel_rate: float = 0.0  # per record: one accelerometer's connector drops out (reads flat 0)
    dead_channel_rate: float = 0.0  # per seating: lifting the disc pulls a cable; flat 0 until the next seating
    mains_hum_m_per_s2: float = 0.0  # amplitude of mains hum on every accelerometer channel (with 3rd harmonic)
    mains_hz: float = 50.0
    creep_rate: float = 0.0  # per knob turn: a loose nut; the step's blows set the load creeping
    creep_n_per_s: float = -1.0  # load change per roller per second of a creeping step
    load_cell_timeout_rate: float = 0.0  # per read: no answer
    load_cell_garbled_rate: float = 0.0  # per read: an unreadable reply
    unequal_seating_rate: float = 0.0  # per seating: one roller sits on a burr or a particle
    unequal_seating_gap_m: float = 1e-6  # height of that layer: adds compliance gap/F to the roller

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not np.isfinite(value):
                raise ValueError(f"fault setting {f.name} = {value!r}: expected a finite number")
            if f.name.endswith("_rate") and not 0.0 <= value <= 1.0:
                raise ValueError(f"fault setting {f.name} = {value!r}: expected a probability in [0, 1]")
            if f.name != "creep_n_per_s" and value < 0:
                raise ValueError(f"fault setting {f.name} = {value!r}: expected a number >= 0")

    @property
    def any(self) -> bool:
        return any(getattr(self, f.name) for f in fields(self) if f.name.endswith("_rate")) or (
            self.mains_hum_m_per_s2 > 0
        )


def mains_hum(n_samples: int, sample_rate_hz: float, amplitude: float, mains_hz: float,
              rng: np.random.Generator, n_channels: int) -> np.ndarray:
    """(channels × samples) hum: the mains frequency plus a third harmonic at a third of the amplitude."""
    t = np.arange(n_samples) / sample_rate_hz
    phase = rng.uniform(0.0, 2.0 * np.pi, (n_channels, 2))
    gain = rng.uniform(0.5, 1.0, (n_channels, 1))  # each cable picks up its own share
    return gain * amplitude * (np.sin(2 * np.pi * mains_hz * t + phase[:, :1])
                               + np.sin(2 * np.pi * 3 * mains_hz * t + phase[:, 1:]) / 3.0)
