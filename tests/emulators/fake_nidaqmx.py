"""Fake ``nidaqmx`` module: Task objects with the real API's method names and parameters (a test compares them
with the real package when it is installed), behaving like an NI 9234 in a cDAQ chassis.

``FakeNiHardware`` is the chassis: which devices are present, the supported sample clock (51.2 kS/s ÷ n),
and the blows to deliver (physical waveforms per channel) the next time a task waits for its trigger.

Maker's facts it enforces (NI USB-9234 User Guide and Specifications: "NI USB-9234 Circuitry", p. 13, and
"Understanding NI USB-9234 Data Rates", p. 15): IEPE current flows only in AC-coupled mode, so a channel left
DC coupled reads no sensor signal (the fake's default coupling is DC, so a missing ``ai_coupling`` is seen);
rates are 13.1072 MHz / 256 / n, n = 1…31 (``rate_rule`` "up" or "nearest" picks how a request is coerced).
The reference trigger's source must be a virtual channel of the task (nidaqmx ``cfg_anlg_edge_ref_trig``:
"the name of a virtual channel or terminal").
"""

from __future__ import annotations

import enum
import time
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import numpy as np


class AcquisitionType(enum.Enum):
    FINITE, CONTINUOUS = 10178, 10123


class Slope(enum.Enum):
    RISING, FALLING = 10280, 10171


class TerminalConfiguration(enum.Enum):
    DEFAULT, PSEUDO_DIFF = -1, 12529


class ExcitationSource(enum.Enum):
    INTERNAL, EXTERNAL, NONE = 10200, 10167, 10230


class AccelUnits(enum.Enum):
    G, METERS_PER_SECOND_SQUARED = 10186, 12470


class AccelSensitivityUnits(enum.Enum):
    MILLIVOLTS_PER_G, VOLTS_PER_G = 12509, 12510


class ForceUnits(enum.Enum):
    NEWTONS, POUNDS = 15875, 15876


class ForceIEPESensorSensitivityUnits(enum.Enum):
    MILLIVOLTS_PER_NEWTON, MILLIVOLTS_PER_POUND = 15891, 15892


class Coupling(enum.Enum):
    AC, DC, GND = 10045, 10050, 10066


class Edge(enum.Enum):
    RISING, FALLING = 10280, 10171


class Error(Exception):
    pass


class DaqError(Error):
    def __init__(self, message: str, error_code: int, task_name: str = "") -> None:
        super().__init__(f"{message}\nStatus Code: {error_code}")
        self.error_code, self.task_name = error_code, task_name


@dataclass
class FakeNiHardware:
    """The chassis and what happens at the rig; ``blow(waveforms)`` queues one impact (name -> values)."""

    devices: tuple[str, ...] = ("cDAQ1Mod1", "cDAQ1Mod2", "cDAQ1Mod3", "cDAQ1Mod4")
    base_rate_hz: float = 13.1072e6 / 256
    rate_rule: str = "up"  # how a requested rate is coerced to 51.2 kS/s ÷ n: "up" or "nearest"
    product_type: str = "NI 9234"
    reserved: bool = False
    removed: bool = False
    blows: list[dict[str, np.ndarray]] = field(default_factory=list)
    tasks: list[FakeTask] = field(default_factory=list)

    def coerce_rate(self, rate: float) -> float:
        supported = [self.base_rate_hz / n for n in range(1, 32)]
        if self.rate_rule == "nearest":
            return min(supported, key=lambda r: abs(r - rate))
        return min((r for r in supported if r >= rate * (1 - 1e-9)), default=self.base_rate_hz)

    def blow(self, waveforms: dict[str, np.ndarray]) -> None:
        self.blows.append(waveforms)

    def module(self) -> SimpleNamespace:
        """What ``import nidaqmx`` would give, wired to this hardware."""
        hardware = self

        def task(new_task_name: str = "") -> FakeTask:
            made = FakeTask(hardware, new_task_name)
            hardware.tasks.append(made)
            return made

        constants = SimpleNamespace(**{c.__name__: c for c in (
            AcquisitionType, Slope, TerminalConfiguration, ExcitationSource, AccelUnits, AccelSensitivityUnits,
            ForceUnits, ForceIEPESensorSensitivityUnits, Edge, Coupling)}, READ_ALL_AVAILABLE=-1)
        local = SimpleNamespace(devices=[SimpleNamespace(name=d, product_type=hardware.product_type)
                                         for d in hardware.devices])
        return SimpleNamespace(Task=task, constants=constants, errors=SimpleNamespace(Error=Error, DaqError=DaqError),
                               system=SimpleNamespace(System=SimpleNamespace(local=lambda: local)))


@dataclass
class _Chan:
    physical: str
    name: str
    kind: str
    min_val: float
    max_val: float
    settings: dict[str, Any]
    ai_coupling: Coupling = Coupling.DC

    @property
    def ai_min(self) -> float:
        return self.min_val

    @property
    def ai_max(self) -> float:
        return self.max_val

    @property
    def ai_excit_val(self) -> float:
        return float(self.settings.get("current_excit_val", 0.0))

    @property
    def ai_excit_src(self) -> Any:
        return self.settings.get("current_excit_source", ExcitationSource.NONE)

    @property
    def powered(self) -> bool:
        """The IEPE sensor gets its current: internal excitation and AC coupling (none in DC-coupled mode)."""
        return (self.settings.get("current_excit_source") is ExcitationSource.INTERNAL
                and self.ai_coupling is Coupling.AC)


class _AIChannels:
    def __init__(self, task: FakeTask) -> None:
        self.task = task
        self.added: list[_Chan] = []

    def __iter__(self) -> Any:
        return iter(self.added)

    def add_ai_accel_chan(self, physical_channel: str, name_to_assign_to_channel: str = "",
                          terminal_config: Any = TerminalConfiguration.DEFAULT, min_val: float = -5.0,
                          max_val: float = 5.0, units: Any = AccelUnits.G, sensitivity: float = 1000.0,
                          sensitivity_units: Any = AccelSensitivityUnits.MILLIVOLTS_PER_G,
                          current_excit_source: Any = ExcitationSource.INTERNAL, current_excit_val: float = 0.004,
                          custom_scale_name: str = "") -> _Chan:
        return self._add(physical_channel, name_to_assign_to_channel, "accel", min_val, max_val, units=units,
                  sensitivity=sensitivity, sensitivity_units=sensitivity_units,
                  current_excit_source=current_excit_source, current_excit_val=current_excit_val)

    def add_ai_force_iepe_chan(self, physical_channel: str, name_to_assign_to_channel: str = "",
                               terminal_config: Any = TerminalConfiguration.DEFAULT, min_val: float = -2000.0,
                               max_val: float = 2000.0, units: Any = ForceUnits.NEWTONS, sensitivity: float = 2.25,
                               sensitivity_units: Any = ForceIEPESensorSensitivityUnits.MILLIVOLTS_PER_NEWTON,
                               current_excit_source: Any = ExcitationSource.INTERNAL,
                               current_excit_val: float = 0.004, custom_scale_name: str = "") -> _Chan:
        return self._add(physical_channel, name_to_assign_to_channel, "force", min_val, max_val, units=units,
                  sensitivity=sensitivity, sensitivity_units=sensitivity_units,
                  current_excit_source=current_excit_source, current_excit_val=current_excit_val)

    def _add(self, physical: str, name: str, kind: str, low: float, high: float, **settings: Any) -> _Chan:
        if physical.split("/")[0] not in self.task.hardware.devices:
            raise DaqError(f"Device identifier is invalid: {physical}", -200220)
        chan = _Chan(physical, name or physical, kind, low, high, settings)
        self.added.append(chan)
        return chan


class _Timing:
    def __init__(self, task: FakeTask) -> None:
        self.task = task
        self.samp_clk_rate = 0.0
        self.samps_per_chan = 0
        self.sample_mode: Any = None

    def cfg_samp_clk_timing(self, rate: float, source: str = "", active_edge: Any = Edge.RISING,
                            sample_mode: Any = AcquisitionType.FINITE, samps_per_chan: int = 1000) -> None:
        self.samp_clk_rate = self.task.hardware.coerce_rate(rate)
        self.samps_per_chan, self.sample_mode = samps_per_chan, sample_mode


class _ReferenceTrigger:
    def __init__(self) -> None:
        self.source: str | None = None
        self.pretrigger = 0
        self.level = 0.0
        self.slope: Any = None

    def cfg_anlg_edge_ref_trig(self, trigger_source: str, pretrigger_samples: int,
                               trigger_slope: Any = Slope.RISING, trigger_level: float = 0.0) -> None:
        self.source, self.pretrigger, self.slope, self.level = trigger_source, pretrigger_samples, trigger_slope, \
            trigger_level


class _InStream:
    def __init__(self) -> None:
        self.overloaded: list[str] = []
        self._asked = False

    @property
    def overloaded_chans_exist(self) -> bool:
        self._asked = True
        return bool(self.overloaded)

    @property
    def overloaded_chans(self) -> list[str]:
        if not self._asked:
            raise DaqError("Read overloaded_chans_exist first", -200507)
        return list(self.overloaded)


class FakeTask:
    def __init__(self, hardware: FakeNiHardware, new_task_name: str = "") -> None:
        self.hardware, self.name = hardware, new_task_name
        self.ai_channels = _AIChannels(self)
        self.timing = _Timing(self)
        self.triggers = SimpleNamespace(reference_trigger=_ReferenceTrigger())
        self.in_stream = _InStream()
        self.running = self.closed = False
        self.starts = 0
        self._data: np.ndarray | None = None

    def start(self) -> None:
        if self.hardware.reserved:
            raise DaqError("The specified resource is reserved.", -50103, self.name)
        trig = self.triggers.reference_trigger
        if trig.source not in {c.name for c in self.ai_channels.added}:
            raise DaqError(f"Trigger source {trig.source!r} is not a virtual channel of the task", -200265, self.name)
        self.running, self._data = True, None
        self.starts += 1

    def stop(self) -> None:
        self.running = False

    def close(self) -> None:
        self.closed, self.running = True, False

    def wait_until_done(self, timeout: float = 10.0) -> None:
        if self.hardware.removed:
            raise DaqError("Device cannot be accessed.", -201003, self.name)
        if not self.hardware.blows:
            time.sleep(timeout)
            raise DaqError("Wait Until Done did not indicate that the task was done within the timeout.",
                           -200560, self.name)
        self._data = self._triggered(self.hardware.blows.pop(0))

    def read(self, number_of_samples_per_channel: Any = -1, timeout: float = 10.0) -> list[list[float]]:
        if self._data is None:
            raise DaqError("Some or all of the samples requested have not yet been acquired.", -200284, self.name)
        return self._data[:, :number_of_samples_per_channel].tolist()

    def _triggered(self, blow: dict[str, np.ndarray]) -> np.ndarray:
        """Place the blow so the first sample at or above the level is the first post-trigger sample."""
        n, trig = self.timing.samps_per_chan, self.triggers.reference_trigger
        source = next(c for c in self.ai_channels.added if c.name == trig.source)
        onset = int(np.argmax(np.asarray(blow[source.name]) >= trig.level))
        data = np.zeros((len(self.ai_channels.added), n))
        for row, chan in enumerate(self.ai_channels.added):
            if not chan.powered:
                continue  # an unpowered IEPE sensor gives no signal
            wave = np.asarray(blow.get(chan.name, np.zeros(n)), dtype=float)[max(0, onset - trig.pretrigger):]
            start = max(0, trig.pretrigger - onset)
            take = min(n - start, wave.size)
            data[row, start:start + take] = np.clip(wave[:take], chan.min_val, chan.max_val)
            if np.any(wave[:take] > chan.max_val) or np.any(wave[:take] < chan.min_val):
                self.in_stream.overloaded.append(chan.name)
        return data
