"""A fake ``nidaqmx`` package behaving as NI 9234 modules in a cDAQ chassis (facts: tests/emulators/MAKER_FACTS.md).

``with installed(Chassis(...)):`` puts ``nidaqmx``, ``nidaqmx.constants``, ``nidaqmx.errors`` and
``nidaqmx.error_codes`` in ``sys.modules``; code under test then imports them as the real package. Names, parameter
names and enum values are the real package's. Time is virtual: sample ``k`` of a task is the input at
``t_start + k / rate``; a trigger that never comes within the read timeout gives the real timeout error.
"""

from __future__ import annotations

import contextlib
import math
import sys
import types
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from enum import Enum

READ_ALL_AVAILABLE = -1
WAIT_INFINITELY = -1.0
_UNSET = object()

MASTER_TIMEBASE_HZ = 13.1072e6
VALID_RATES_HZ = tuple(MASTER_TIMEBASE_HZ / 256 / n for n in range(1, 32))  # 51.2 kS/s / n, n = 1..31
INPUT_RANGE_V = 5.0
IEPE_CURRENT_A = 0.002
G_M_PER_S2 = 9.80665


# -- nidaqmx.constants (values as in the real package) ---------------------------------------------------------------
class AcquisitionType(Enum):
    FINITE = 10178
    CONTINUOUS = 10123
    HW_TIMED_SINGLE_POINT = 12522


class AccelUnits(Enum):
    G = 10186
    METERS_PER_SECOND_SQUARED = 12470
    INCHES_PER_SECOND_SQUARED = 12471
    FROM_CUSTOM_SCALE = 10065


class AccelSensitivityUnits(Enum):
    MILLIVOLTS_PER_G = 12509
    VOLTS_PER_G = 12510
    M_VOLTS_PER_G = 12509  # the spelling of older nidaqmx releases (an alias of the same value)


class Coupling(Enum):
    AC = 10045
    DC = 10050
    GND = 10066


class Edge(Enum):
    RISING = 10280
    FALLING = 10171


class Slope(Enum):
    RISING = 10280
    FALLING = 10171


class ExcitationSource(Enum):
    INTERNAL = 10200
    EXTERNAL = 10167
    NONE = 10230


class TerminalConfiguration(Enum):
    RSE = 10083
    NRSE = 10078
    DIFF = 10106
    PSEUDO_DIFF = 12529
    DEFAULT = -1


class TriggerType(Enum):
    ANALOG_EDGE = 10099
    DIGITAL_EDGE = 10150
    NONE = 10230


class VoltageUnits(Enum):
    VOLTS = 10348
    FROM_CUSTOM_SCALE = 10065


# -- nidaqmx.errors / error_codes --------------------------------------------------------------------------------------
class DAQmxErrors(Enum):
    UNKNOWN = -1
    INVALID_ATTRIBUTE_VALUE = -200077
    PHYSICAL_CHAN_DOES_NOT_EXIST = -200170
    TOO_MANY_PRETRIG_PLUS_MIN_POST_TRIG_SAMPS = -200213
    INVALID_ANALOG_TRIG_SRC = -200265
    SAMPLES_WILL_NEVER_BE_AVAILABLE = -200278
    SAMPLES_NOT_YET_AVAILABLE = -200284
    REF_TRIG_WHEN_CONTINUOUS = -200358
    WAIT_UNTIL_DONE_DOES_NOT_INDICATE_DONE = -200560


class Error(Exception):
    pass


class DaqError(Error):
    """Same constructor and properties as nidaqmx.errors.DaqError."""

    def __init__(self, message: str, error_code: int, task_name: str = "") -> None:
        if task_name:
            message = f"{message}\n\nTask Name: {task_name}"
        super().__init__(message)
        self._error_code = int(error_code)
        try:
            self._error_type = DAQmxErrors(self._error_code)
        except ValueError:
            self._error_type = DAQmxErrors.UNKNOWN

    @property
    def error_code(self) -> int:
        return self._error_code

    @property
    def error_type(self) -> DAQmxErrors:
        return self._error_type


class DaqReadError(DaqError):
    def __init__(self, message: str, error_code: int, samps_per_chan_read: int, task_name: str = "") -> None:
        super().__init__(message, error_code, task_name)
        self.samps_per_chan_read = samps_per_chan_read


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


# -- task objects ----------------------------------------------------------------------------------------------------
class _Chan:
    def __init__(self, physical: str, name: str, source: Input, kind: str, **cfg: object) -> None:
        self.physical, self.name, self.source, self.kind = physical, name, source, kind
        self.min_val = float(cfg["min_val"])
        self.max_val = float(cfg["max_val"])
        self.units = cfg.get("units")
        self.sensitivity_v_per_unit = 1.0
        if kind == "accel":
            sens = float(cfg["sensitivity"])
            sens_v_per_g = sens * 1e-3 if cfg["sensitivity_units"] == AccelSensitivityUnits.MILLIVOLTS_PER_G else sens
            per_unit = sens_v_per_g / G_M_PER_S2 if self.units == AccelUnits.METERS_PER_SECOND_SQUARED else sens_v_per_g
            self.sensitivity_v_per_unit = per_unit
            self.ai_excit_src = cfg["current_excit_source"]
            self.ai_excit_val = float(cfg["current_excit_val"])
            self.ai_coupling = Coupling.AC
        else:
            self.ai_excit_src, self.ai_excit_val, self.ai_coupling = ExcitationSource.NONE, 0.0, Coupling.DC

    def excitation_on(self) -> bool:
        return self.ai_excit_src == ExcitationSource.INTERNAL and self.ai_excit_val > 0

    def verify(self, task: str) -> None:
        def bad(prop: str, value: object, possible: str) -> DaqError:
            return DaqError(f"Requested value is not a supported value for this property. The property value may be "
                            f"invalid because it conflicts with another property.\nProperty: {prop}\nRequested Value: "
                            f"{value}\nPossible Values: {possible}\nChannel Name: {self.name}", -200077, task)
        if self.ai_excit_src == ExcitationSource.INTERNAL and not math.isclose(self.ai_excit_val, IEPE_CURRENT_A):
            raise bad("AI.Excit.Val", self.ai_excit_val, "2.0e-3")
        if self.ai_excit_src == ExcitationSource.EXTERNAL:
            raise bad("AI.Excit.Src", "External", "Internal, None")
        if self.excitation_on() and self.ai_coupling != Coupling.AC:
            raise bad("AI.Coupling", self.ai_coupling.name, "AC")  # IEPE current only in AC-coupled mode
        if self.ai_coupling == Coupling.GND:
            raise bad("AI.Coupling", "GND", "AC, DC")
        for prop, v in (("AI.Max", self.max_val), ("AI.Min", self.min_val)):
            if abs(v * self.sensitivity_v_per_unit) > INPUT_RANGE_V * (1 + 1e-9):
                raise bad(prop, v, f"{-INPUT_RANGE_V / self.sensitivity_v_per_unit} to "
                          f"{INPUT_RANGE_V / self.sensitivity_v_per_unit}")

    def input_volts(self, t: float) -> float:
        """Voltage at the BNC: an unpowered IEPE sensor is silent; a powered one rides on its DC bias."""
        src = self.source
        if src.iepe_sensor and not self.excitation_on():
            return 0.0
        return src.volts(t) + (src.iepe_bias_v if src.iepe_sensor else 0.0)

    def scaled(self, volts: float) -> float:
        return max(-INPUT_RANGE_V, min(INPUT_RANGE_V, volts)) / self.sensitivity_v_per_unit


class AIChannel:
    """The object ``add_ai_*_chan`` returns; property writes apply to every channel it names."""

    def __init__(self, chans: list[_Chan]) -> None:
        object.__setattr__(self, "_chans", chans)

    def __getattr__(self, name: str) -> object:
        return getattr(self._chans[0], name)

    def __setattr__(self, name: str, value: object) -> None:
        for c in self._chans:
            setattr(c, name, value)


class AIChannelCollection:
    def __init__(self, task: Task) -> None:
        self._task = task

    def __getitem__(self, index: int) -> AIChannel:
        return AIChannel([self._task._chans[index]])

    def __len__(self) -> int:
        return len(self._task._chans)

    def _add(self, physical_channel: str, name: str, kind: str, **cfg: object) -> AIChannel:
        chassis = _ACTIVE[-1]
        made = []
        for i, phys in enumerate(_expand(physical_channel)):
            chan_name = (name if i == 0 else f"{name}{i}") if name else phys
            made.append(_Chan(phys, chan_name, chassis.physical(phys), kind, **cfg))
        self._task._chans += made
        return AIChannel(made)

    def add_ai_accel_chan(self, physical_channel, name_to_assign_to_channel="",
                          terminal_config=TerminalConfiguration.DEFAULT, min_val=-5.0, max_val=5.0,
                          units=AccelUnits.G, sensitivity=1000.0,
                          sensitivity_units=AccelSensitivityUnits.MILLIVOLTS_PER_G,
                          current_excit_source=ExcitationSource.INTERNAL, current_excit_val=0.004,
                          custom_scale_name=""):
        return self._add(physical_channel, name_to_assign_to_channel, "accel", min_val=min_val, max_val=max_val,
                         units=units, sensitivity=sensitivity, sensitivity_units=sensitivity_units,
                         current_excit_source=current_excit_source, current_excit_val=current_excit_val)

    def add_ai_voltage_chan(self, physical_channel, name_to_assign_to_channel="",
                            terminal_config=TerminalConfiguration.DEFAULT, min_val=-5.0, max_val=5.0,
                            units=VoltageUnits.VOLTS, custom_scale_name=""):
        return self._add(physical_channel, name_to_assign_to_channel, "voltage", min_val=min_val, max_val=max_val,
                         units=units)


class Timing:
    def __init__(self, task: Task) -> None:
        self._task = task
        self._rate = None
        self.samp_quant_samp_mode = AcquisitionType.FINITE
        self.samp_quant_samp_per_chan = 1000

    def cfg_samp_clk_timing(self, rate, source="", active_edge=Edge.RISING, sample_mode=AcquisitionType.FINITE,
                            samps_per_chan=1000):
        self._rate = float(rate)
        self.samp_quant_samp_mode = sample_mode
        self.samp_quant_samp_per_chan = int(samps_per_chan)

    @property
    def samp_clk_rate(self) -> float:
        return coerce_rate(self._rate if self._rate is not None else VALID_RATES_HZ[0], self._task.name)

    @samp_clk_rate.setter
    def samp_clk_rate(self, value: float) -> None:
        self._rate = float(value)


class _Trigger:
    def __init__(self) -> None:
        self.trig_type = TriggerType.NONE
        self.source = ""
        self.rising = True
        self.level = 0.0
        self.pretrig_samples = 0


class StartTrigger(_Trigger):
    def cfg_dig_edge_start_trig(self, trigger_source, trigger_edge=Edge.RISING):
        self.trig_type, self.source, self.rising = TriggerType.DIGITAL_EDGE, trigger_source, trigger_edge == Edge.RISING

    def cfg_anlg_edge_start_trig(self, trigger_source="", trigger_slope=Slope.RISING, trigger_level=0.0):
        self.trig_type, self.source = TriggerType.ANALOG_EDGE, trigger_source
        self.rising, self.level = trigger_slope == Slope.RISING, float(trigger_level)

    def disable_start_trig(self):
        self.trig_type = TriggerType.NONE


class ReferenceTrigger(_Trigger):
    def cfg_anlg_edge_ref_trig(self, trigger_source, pretrigger_samples, trigger_slope=Slope.RISING,
                               trigger_level=0.0):
        self.trig_type, self.source, self.pretrig_samples = TriggerType.ANALOG_EDGE, trigger_source, pretrigger_samples
        self.rising, self.level = trigger_slope == Slope.RISING, float(trigger_level)

    def cfg_dig_edge_ref_trig(self, trigger_source, pretrigger_samples, trigger_edge=Edge.RISING):
        self.trig_type, self.source, self.pretrig_samples = TriggerType.DIGITAL_EDGE, trigger_source, pretrigger_samples
        self.rising = trigger_edge == Edge.RISING

    def disable_ref_trig(self):
        self.trig_type = TriggerType.NONE


class Triggers:
    def __init__(self) -> None:
        self.start_trigger = StartTrigger()
        self.reference_trigger = ReferenceTrigger()


SEARCH_LIMIT_S = 30.0  # virtual seconds searched for a trigger when the timeout is infinite


class Task:
    """nidaqmx.Task for NI 9234 channels: configure, start (verify as DAQmx does), read, stop, close."""

    def __init__(self, new_task_name: str = "") -> None:
        if not _ACTIVE:
            raise RuntimeError("no emulated chassis installed (use maker_ni9234.installed)")
        self._chassis = _ACTIVE[-1]
        self.name = new_task_name or f"_unnamedTask<{id(self):x}>"
        self._chans: list[_Chan] = []
        self.ai_channels = AIChannelCollection(self)
        self.timing = Timing(self)
        self.triggers = Triggers()
        self.in_stream = InStream(self)
        self._running = False
        self._closed = False

    def __enter__(self) -> Task:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def channel_names(self) -> list[str]:
        return [c.name for c in self._chans]

    @property
    def number_of_channels(self) -> int:
        return len(self._chans)

    # -- lifecycle -----------------------------------------------------------------------------------------------
    def start(self) -> None:
        for chan in self._chans:
            chan.verify(self.name)
        self._rate = self.timing.samp_clk_rate
        finite = self.timing.samp_quant_samp_mode == AcquisitionType.FINITE
        ref = self.triggers.reference_trigger
        if ref.trig_type != TriggerType.NONE:
            if not finite:
                raise DaqError("Reference Trigger cannot be used with continuous sample mode.", -200358, self.name)
            if ref.pretrig_samples + 2 > self.timing.samp_quant_samp_per_chan:
                raise DaqError("Pretrigger samples plus minimum posttrigger samples (2) exceed samples per channel.",
                               -200213, self.name)
        for trig in (self.triggers.start_trigger, ref):
            if trig.trig_type == TriggerType.ANALOG_EDGE:
                self._trigger_chan(trig)
        self._volts: list[list[float]] = [[] for _ in self._chans]
        self._hp_state = [(0.0, None) for _ in self._chans]
        self._record_start: int | None = None
        self._read_pos = 0
        self._running = True

    def stop(self) -> None:
        self._running = False

    def close(self) -> None:
        self._running = False
        self._closed = True

    def is_task_done(self) -> bool:
        return not self._running or self._finite_total() is not None and self._read_pos >= self._finite_total()

    def wait_until_done(self, timeout: float = 10.0) -> None:
        if self._locate_record(timeout) is None:
            raise DaqError("Wait Until Done did not indicate all samples were acquired.", -200560, self.name)

    # -- acquisition -------------------------------------------------------------------------------------------------
    def _trigger_chan(self, trig: _Trigger) -> int:
        for i, c in enumerate(self._chans):
            if c.physical.strip("/") == trig.source.strip("/") or c.name == trig.source:
                return i
        raise DaqError(f"Analog trigger source must be a channel in the task: {trig.source}", -200265, self.name)

    def _finite_total(self) -> int | None:
        if self.timing.samp_quant_samp_mode == AcquisitionType.FINITE:
            return self.timing.samp_quant_samp_per_chan
        return None

    def _fill(self, n: int) -> None:
        """Extend every channel's stream of ADC input volts (AC coupling as a first-order high-pass) to ``n``."""
        dt = 1.0 / self._rate
        alpha = 1.0 / (1.0 + 2 * math.pi * self._chassis.ac_cutoff_hz * dt)
        for i, chan in enumerate(self._chans):
            out = self._volts[i]
            y, x_prev = self._hp_state[i]
            for k in range(len(out), n):
                x = chan.input_volts(k * dt)
                if chan.ai_coupling == Coupling.AC:
                    bias = chan.source.iepe_bias_v if chan.source.iepe_sensor and chan.excitation_on() else 0.0
                    x -= bias  # the coupling capacitor has charged to the sensor's bias before the task runs
                    y = alpha * (y + x - x_prev) if x_prev is not None else x
                    x_prev = x
                    out.append(y)
                else:
                    out.append(x)
            self._hp_state[i] = (y, x_prev)

    def _value(self, chan: int, k: int) -> float:
        self._fill(k + 1)
        return self._chans[chan].scaled(self._volts[chan][k])

    def _find_edge(self, trig: _Trigger, first: int, last: int) -> int | None:
        if trig.trig_type == TriggerType.DIGITAL_EDGE:
            edges = [t for t in self._chassis.digital_edges_s.get(trig.source, []) if t >= first / self._rate]
            k = math.ceil(min(edges) * self._rate) if edges else None
            return k if k is not None and k <= last else None
        ci = self._trigger_chan(trig)
        prev = self._value(ci, max(first - 1, 0))
        for k in range(max(first, 1), last + 1):
            cur = self._value(ci, k)
            if (trig.rising and prev < trig.level <= cur) or (not trig.rising and prev > trig.level >= cur):
                return k
            prev = cur
        return None

    def _locate_record(self, timeout: float) -> int | None:
        if self._record_start is not None:
            return self._record_start
        horizon = int((SEARCH_LIMIT_S if timeout < 0 else timeout) * self._rate)
        start = 0
        st = self.triggers.start_trigger
        if st.trig_type != TriggerType.NONE:
            found = self._find_edge(st, 0, horizon)
            if found is None:
                return None
            start = found
        ref = self.triggers.reference_trigger
        if ref.trig_type != TriggerType.NONE:
            found = self._find_edge(ref, start + ref.pretrig_samples, start + horizon)
            if found is None:
                return None
            start = found - ref.pretrig_samples
        self._record_start = start
        return start

    def read(self, number_of_samples_per_channel=_UNSET, timeout=10.0):
        if not self._running:
            self.start()
        n = 1 if number_of_samples_per_channel is _UNSET else int(number_of_samples_per_channel)
        total = self._finite_total()
        if n == READ_ALL_AVAILABLE:
            n = (total - self._read_pos) if total is not None else int(self._rate * 0.1)
        if total is not None and self._read_pos + n > total:
            raise DaqError("Requested samples will never be available (beyond the end of a finite acquisition).",
                           -200278, self.name)
        start = self._locate_record(timeout)
        if start is None:
            raise DaqReadError("Some or all of the samples requested have not yet been acquired.\n\n"
                               "To wait for the samples to become available use a longer read timeout or read later "
                               "in your program.", -200284, 0, self.name)
        first = start + self._read_pos
        data = [[self._value(i, k) for k in range(first, first + n)] for i in range(len(self._chans))]
        self._read_pos += n
        if len(self._chans) == 1:
            return data[0][0] if number_of_samples_per_channel is _UNSET else data[0]
        return [d[0] for d in data] if number_of_samples_per_channel is _UNSET else data


class InStream:
    """``task.in_stream``: what the stream readers read through."""

    def __init__(self, task: Task) -> None:
        self._task = task

    @property
    def avail_samp_per_chan(self) -> int:
        total = self._task._finite_total()
        return (total - self._task._read_pos) if total is not None else int(self._task._rate * 0.1)


class AnalogMultiChannelReader:
    """nidaqmx.stream_readers.AnalogMultiChannelReader: fills a (channels, samples) float64 array."""

    def __init__(self, task_in_stream: InStream) -> None:
        self._in_stream = task_in_stream

    def read_many_sample(self, data, number_of_samples_per_channel=READ_ALL_AVAILABLE, timeout=10.0) -> int:
        task = self._in_stream._task
        n = number_of_samples_per_channel
        if n == READ_ALL_AVAILABLE:
            n = data.shape[-1]
        values = task.read(n, timeout)
        rows = [values] if task.number_of_channels == 1 else values
        for i, row in enumerate(rows):
            data.reshape(len(rows), -1)[i, :n] = row
        return n


class AnalogSingleChannelReader(AnalogMultiChannelReader):
    """nidaqmx.stream_readers.AnalogSingleChannelReader: fills a 1-D float64 array."""


# -- installing the fake package --------------------------------------------------------------------------------------
def _modules() -> dict[str, types.ModuleType]:
    pkg = types.ModuleType("nidaqmx")
    constants = types.ModuleType("nidaqmx.constants")
    errors = types.ModuleType("nidaqmx.errors")
    error_codes = types.ModuleType("nidaqmx.error_codes")
    readers = types.ModuleType("nidaqmx.stream_readers")
    readers.AnalogMultiChannelReader, readers.AnalogSingleChannelReader = (AnalogMultiChannelReader,
                                                                           AnalogSingleChannelReader)
    for enum_cls in (AcquisitionType, AccelUnits, AccelSensitivityUnits, Coupling, Edge, Slope, ExcitationSource,
                     TerminalConfiguration, TriggerType, VoltageUnits):
        setattr(constants, enum_cls.__name__, enum_cls)
    constants.READ_ALL_AVAILABLE, constants.WAIT_INFINITELY = READ_ALL_AVAILABLE, WAIT_INFINITELY
    errors.Error, errors.DaqError, errors.DaqReadError = Error, DaqError, DaqReadError
    error_codes.DAQmxErrors = DAQmxErrors
    pkg.Task, pkg.constants, pkg.errors, pkg.error_codes = Task, constants, errors, error_codes
    pkg.stream_readers = readers
    pkg.DaqError = DaqError
    pkg.__path__ = []  # a package, so ``import nidaqmx.constants`` resolves through sys.modules
    return {"nidaqmx": pkg, "nidaqmx.constants": constants, "nidaqmx.errors": errors,
            "nidaqmx.error_codes": error_codes, "nidaqmx.stream_readers": readers}


@contextlib.contextmanager
def installed(chassis: Chassis) -> Iterator[types.ModuleType]:
    """Make ``import nidaqmx`` give this emulator wired to ``chassis`` for the duration of the block."""
    modules = _modules()
    saved = {name: sys.modules.get(name) for name in modules}
    sys.modules.update(modules)
    _ACTIVE.append(chassis)
    try:
        yield modules["nidaqmx"]
    finally:
        _ACTIVE.remove(chassis)
        for name, mod in saved.items():
            if mod is None:
                sys.modules.pop(name, None)
            else:
                sys.modules[name] = mod
