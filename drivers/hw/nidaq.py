"""NI-DAQmx adapter (e.g. an NI 9234 in a cDAQ chassis): IEPE accelerometer and force channels with their
sensitivities, the sample clock as the device actually sets it, an analog reference trigger with pretrigger.

``nidaqmx`` is the optional extra ``hw`` and is imported only when the adapter is used, so labctl works
without it. The module can be injected (``nidaqmx_module``) to run the adapter against fake task objects.
"""

from __future__ import annotations

import contextlib
import importlib
import time
from collections.abc import Iterator, Sequence
from types import ModuleType
from typing import Any

import numpy as np

from drivers.errors import DeviceBusy, DeviceDisconnected, DeviceError, DeviceTimeout
from drivers.hw.acquisition import InputWiring, check_wiring, make_record
from drivers.hw.lifecycle import Lifecycle
from drivers.interfaces import Channel, Record, TriggerSpec

STANDARD_GRAVITY_M_PER_S2 = 9.80665
TIMEOUT_CODES = {-200284, -200560, -200221}  # samples not yet available, wait-until-done, timeout exceeded
BUSY_CODES = {-50103, -200022}  # resource reserved by another task
GONE_CODES = {-201003, -200220, -201401}  # device cannot be accessed / not present / removed


def ni_error(device: str, action: str, exc: Exception) -> DeviceError:
    """A DAQmx error as the typed error, keeping NI's code and message."""
    code = getattr(exc, "error_code", None)
    text = " ".join(str(exc).split())[:300]
    if code in TIMEOUT_CODES:
        return DeviceTimeout(device, action, f"DAQmx {code}: {text}")
    if code in BUSY_CODES:
        return DeviceBusy(device, action, f"in use by another task (DAQmx {code})")
    if code in GONE_CODES:
        return DeviceDisconnected(device, action, f"device not present (DAQmx {code}): {text}")
    if type(exc).__name__ == "DaqNotFoundError":
        return DeviceError(device, action, "the NI-DAQmx driver is not installed on this computer")
    return DeviceError(device, action, f"DAQmx {code}: {text}" if code is not None else text)


class NiDaq(Lifecycle):
    """A finite, reference-triggered acquisition of every wired channel; ``configure`` returns the real rate."""

    def __init__(self, wiring: Sequence[InputWiring], *, iepe_current_a: float = 0.002, name: str = "daq@nidaqmx",
                 nidaqmx_module: ModuleType | Any = None) -> None:
        self.name = name
        self._force_row, _ = check_wiring(name, wiring)
        self._wiring = tuple(wiring)
        self.iepe_current_a = iepe_current_a
        self._ni = nidaqmx_module
        self._task: Any = None
        self._rate_hz = 0.0
        self._n_samples = 0
        self._pretrigger: int | None = None  # set by arm, cleared by acquire
        self.requested_rate_hz = 0.0

    @property
    def channels(self) -> tuple[Channel, ...]:
        return tuple(w.channel for w in self._wiring)

    @property
    def sample_rate_hz(self) -> float:
        return self._rate_hz

    def open(self) -> None:
        self._module()

    def close(self) -> None:
        if self._task is not None:
            with contextlib.suppress(Exception):  # closing must not hide the error that led here
                self._task.close()
        self._task = None


    def configure(self, sample_rate_hz: float, n_samples: int) -> float:
        """Create the task; the sample clock is read back (an NI 9234 coerces 20 480 Hz to 25 600 Hz)."""
        ni = self._module()
        self.close()
        self.requested_rate_hz, self._n_samples = float(sample_rate_hz), int(n_samples)
        with self._errors("configure"):
            self._task = ni.Task()
            for w in self._wiring:
                self._add_channel(ni, w)
            self._task.timing.cfg_samp_clk_timing(sample_rate_hz, sample_mode=ni.constants.AcquisitionType.FINITE,
                                                  samps_per_chan=self._n_samples)
            self._rate_hz = float(self._task.timing.samp_clk_rate)
        return self._rate_hz

    def arm(self, trigger: TriggerSpec) -> None:
        """Reference trigger on the force channel rising through ``level_n``, ``pretrigger_samples`` kept."""
        if self._task is None:
            raise DeviceError(self.name, "arm", "configure() first")
        ni = self._module()
        force = self._wiring[self._force_row]
        with self._errors("arm"):
            self._task.stop()
            self._task.triggers.reference_trigger.cfg_anlg_edge_ref_trig(
                force.terminal, pretrigger_samples=trigger.pretrigger_samples,
                trigger_slope=ni.constants.Slope.RISING, trigger_level=trigger.level_n)
            self._task.start()
        self._pretrigger = trigger.pretrigger_samples

    def acquire(self, timeout_s: float) -> Record:
        """Wait for the trigger and the post-trigger samples; read all channels in physical units."""
        if self._task is None or self._pretrigger is None:
            raise DeviceError(self.name, "acquire", "not armed: call arm() before acquire()")
        pretrigger, self._pretrigger = self._pretrigger, None
        record_s = self._n_samples / self._rate_hz
        with self._errors("acquire"):
            self._task.wait_until_done(timeout=timeout_s + record_s)
            data = np.asarray(self._task.read(number_of_samples_per_channel=self._n_samples, timeout=1.0), float)
            overloaded = self._overloaded()
            self._task.stop()
        data = data.reshape(len(self._wiring), self._n_samples)
        return make_record(self._wiring, data, self._rate_hz, pretrigger, time.time() - record_s, overloaded)

    def probe(self) -> str:
        ni = self._module()
        devices = sorted({w.terminal.split("/")[0] for w in self._wiring})
        with self._errors("probe"):
            system = ni.system.System.local()
            present = {d.name for d in system.devices}
        missing = [d for d in devices if d not in present]
        if missing:
            raise DeviceDisconnected(self.name, "probe", f"not present: {', '.join(missing)} "
                                     f"(present: {', '.join(sorted(present)) or 'none'})")
        return f"NI-DAQmx devices {', '.join(devices)} present, {len(self._wiring)} channels"

    def _add_channel(self, ni: Any, w: InputWiring) -> None:
        c, k = w.channel, ni.constants
        common = dict(name_to_assign_to_channel=c.name, min_val=-c.range_units, max_val=c.range_units,
                      current_excit_source=k.ExcitationSource.INTERNAL, current_excit_val=self.iepe_current_a)
        if c.kind == "force":
            self._task.ai_channels.add_ai_force_iepe_chan(
                w.terminal, units=k.ForceUnits.NEWTONS, sensitivity=c.sensitivity_v_per_unit * 1e3,
                sensitivity_units=k.ForceIEPESensorSensitivityUnits.MILLIVOLTS_PER_NEWTON, **common)
        else:
            mv_per_g = c.sensitivity_v_per_unit * 1e3 * STANDARD_GRAVITY_M_PER_S2
            self._task.ai_channels.add_ai_accel_chan(
                w.terminal, units=k.AccelUnits.METERS_PER_SECOND_SQUARED, sensitivity=mv_per_g,
                sensitivity_units=k.AccelSensitivityUnits.MILLIVOLTS_PER_G, **common)

    def _overloaded(self) -> list[str]:
        stream = self._task.in_stream
        try:
            return list(stream.overloaded_chans) if stream.overloaded_chans_exist else []
        except self._module().errors.Error:
            return []  # the device cannot report overloads

    def _module(self) -> Any:
        if self._ni is None:
            try:
                self._ni = importlib.import_module("nidaqmx")
            except ImportError:
                raise DeviceError(self.name, "open", "the nidaqmx package is not installed "
                                  "(pip install 'labctl[hw]')") from None
        return self._ni

    @contextlib.contextmanager
    def _errors(self, action: str) -> Iterator[None]:
        """Turn DAQmx exceptions raised inside the block into typed device errors."""
        daqmx_error = self._module().errors.Error
        try:
            yield
        except daqmx_error as exc:
            raise ni_error(self.name, action, exc) from exc
