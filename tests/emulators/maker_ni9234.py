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
from collections.abc import Iterator

from tests.emulators.maker_ni9234_api import (  # noqa: F401 - re-exported: the fake package's names
    READ_ALL_AVAILABLE,
    WAIT_INFINITELY,
    AccelSensitivityUnits,
    AccelUnits,
    AcquisitionType,
    Coupling,
    DaqError,
    DAQmxErrors,
    DaqReadError,
    Edge,
    Error,
    ExcitationSource,
    Slope,
    TerminalConfiguration,
    TriggerType,
    VoltageUnits,
)
from tests.emulators.maker_ni9234_channels import (  # noqa: F401 - re-exported: the fake package's objects
    AIChannel,
    AIChannelCollection,
    ReferenceTrigger,
    StartTrigger,
    Timing,
    Triggers,
    _Chan,
    _Trigger,
)
from tests.emulators.maker_ni9234_chassis import (  # noqa: F401 - re-exported: the simulated hardware
    _ACTIVE,
    _UNSET,
    G_M_PER_S2,
    IEPE_CURRENT_A,
    INPUT_RANGE_V,
    MASTER_TIMEBASE_HZ,
    VALID_RATES_HZ,
    Chassis,
    Input,
    coerce_rate,
)

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
