"""The NI 9234 emulator's simulated hardware: the modules' inputs in a cDAQ chassis and the sample clock's
rates (facts: tests/emulators/MAKER_FACTS.md)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from tests.emulators.maker_ni9234_api import DaqError

_UNSET = object()

MASTER_TIMEBASE_HZ = 13.1072e6
VALID_RATES_HZ = tuple(MASTER_TIMEBASE_HZ / 256 / n for n in range(1, 32))  # 51.2 kS/s / n, n = 1..31
INPUT_RANGE_V = 5.0
IEPE_CURRENT_A = 0.002
G_M_PER_S2 = 9.80665


# -- the simulated hardware --------------------------------------------------------------------------------------------
Volts = Callable[[float], float]


@dataclass
class Input:
    """What is wired to one BNC: ``volts(t)`` is the sensor's signal; an IEPE sensor gives it only when fed 2 mA."""

    volts: Volts = lambda t: 0.0
    iepe_sensor: bool = True
    iepe_bias_v: float = 11.0  # DC bias of a powered IEPE sensor, removed by AC coupling


@dataclass
class Chassis:
    """A cDAQ chassis ``name`` with NI 9234 modules in slots (``{slot: {ai index: Input}}``) and PFI edge times."""

    name: str = "cDAQ1"
    modules: dict[int, dict[int, Input]] = field(default_factory=lambda: {1: {}})
    digital_edges_s: dict[str, list[float]] = field(default_factory=dict)  # e.g. {"/cDAQ1/PFI0": [0.02]}
    ac_cutoff_hz: float = 0.5

    def physical(self, name: str) -> Input:
        dev, _, chan = name.strip().strip("/").partition("/")
        prefix = f"{self.name}Mod"
        if not dev.startswith(prefix) or not chan.startswith("ai"):
            raise DaqError(f"Physical channel specified does not exist on this device: {name}", -200170)
        slot, index = dev[len(prefix):], chan[2:]
        if not (slot.isdigit() and index.isdigit()) or int(slot) not in self.modules or int(index) > 3:
            raise DaqError(f"Physical channel specified does not exist on this device: {name}", -200170)
        return self.modules[int(slot)].setdefault(int(index), Input())


_ACTIVE: list[Chassis] = []


def _expand(physical_channel: str) -> list[str]:
    names: list[str] = []
    for part in physical_channel.split(","):
        part = part.strip()
        dev, _, chans = part.rpartition("/")
        if ":" in chans:
            lo, hi = chans[2:].split(":")
            names += [f"{dev}/ai{i}" for i in range(int(lo), int(hi) + 1)]
        else:
            names.append(part)
    return names


def coerce_rate(rate_hz: float, task_name: str = "") -> float:
    """DAQmx coerces a DSA rate up to the next rate the module makes (51.2 kS/s / n); outside the range it errs."""
    if not VALID_RATES_HZ[-1] * (1 - 1e-12) <= rate_hz <= VALID_RATES_HZ[0] * (1 + 1e-12):
        raise DaqError("Requested value is not a supported value for this property.\nProperty: SampClk.Rate\n"
                       f"Requested Value: {rate_hz}\nPossible Values: {VALID_RATES_HZ[-1]} to {VALID_RATES_HZ[0]}",
                       -200077, task_name)
    return min(r for r in VALID_RATES_HZ if r >= rate_hz * (1 - 1e-12))
