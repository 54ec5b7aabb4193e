"""A small wired MCC setup and an impact as input volts, shared by the DAQ and hammer tests."""

from __future__ import annotations

import numpy as np

from drivers.hw.acquisition import InputWiring
from drivers.interfaces import Channel, TriggerSpec

FORCE_V_PER_N = 0.23e-3  # PCB 086D05
ACCEL_V_PER_MS2 = 0.1 / 9.80665  # 100 mV/g
FS, N, PRE = 20480.0, 4096, 256
TRIGGER = TriggerSpec(level_n=20.0, pretrigger_samples=PRE)


def wiring() -> list[InputWiring]:
    """Force on input 0, A1Z on input 2, A2Z on input 1: the scan order differs from the wiring order."""
    return [
        InputWiring(Channel("F", "force", "N", FORCE_V_PER_N, 2200.0), "0"),
        InputWiring(Channel("A1Z", "acceleration", "m/s^2", ACCEL_V_PER_MS2, 490.0), "2"),
        InputWiring(Channel("A2Z", "acceleration", "m/s^2", ACCEL_V_PER_MS2, 490.0), "1"),
    ]


def impact_volts(fs: float, peak_n: float = 600.0, n: int = N) -> np.ndarray:
    """Input volts (8, n): a 0.3 ms half-sine force on input 0, decaying responses on inputs 1 and 2."""
    t = np.arange(n) / fs
    width = 0.3e-3
    force = np.where(t < width, peak_n * np.sin(np.pi * t / width), 0.0)
    volts = np.zeros((8, n))
    volts[0] = force * FORCE_V_PER_N
    volts[2] = 200.0 * np.exp(-40 * t) * np.sin(2 * np.pi * 745 * t) * ACCEL_V_PER_MS2
    volts[1] = -80.0 * np.exp(-40 * t) * np.sin(2 * np.pi * 581 * t) * ACCEL_V_PER_MS2
    return volts
