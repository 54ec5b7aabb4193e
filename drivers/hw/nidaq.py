"""NI-DAQmx adapter (e.g. an NI 9234 in a cDAQ chassis): IEPE accelerometer and force channels with their
sensitivities, AC coupled (the NI 9234 supplies IEPE current only in AC-coupled mode), the sample clock as the
device actually sets it, and an analog reference trigger on the force channel with pretrigger.

The record is a duration, not a sample count: ``configure(rate, n)`` asks for ``n / rate`` seconds, and the
sample count (and, at ``arm``, the pretrigger) is re-derived from the rate the device really runs at, so an
NI 9234 asked for 20 480 Hz × 65 536 samples records 3.2 s at 25 600 Hz (81 920 samples), not 2.56 s.

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
from drivers.hw.acquisition import InputWiring, check_wiring, make_record, samples_at_rate
from drivers.hw.lifecycle import Lifecycle
from drivers.hw.verify import FAILED, NOT_VERIFIED, VERIFIED, Finding
from drivers.interfaces import Channel, Record, TriggerSpec

STANDARD_GRAVITY_M_PER_S2 = 9.80665
# nidaqmx.error_codes.DAQmxErrors names
TIMEOUT_CODES = {-200284, -200560, -200221}  # SAMPLES_NOT_YET_AVAILABLE, WAIT_UNTIL_DONE_DOES_NOT_INDICATE_DONE,
#                                              TIMEOUT_EXCEEDED
BUSY_CODES = {-50103, -200022}  # PAL_RESOURCE_RESERVED, RESOURCE_ALREADY_RESERVED
GONE_CODES = {-201003: "device cannot be accessed", -200220: "device identifier is invalid (not present)",
              -200045: "device removed"}  # DEV_CANNOT_BE_ACCESSED, INVALID_DEVICE_ID, DEVICE_REMOVED
UNREACHABLE_CODE = -201401  # RETRIEVING_NETWORK_DEVICE_PROPERTIES: a network chassis did not answer


def import_nidaqmx(device: str) -> Any:
    """The nidaqmx package, or a DeviceError saying how to install it (it is an optional extra)."""
    try:
        return importlib.import_module("nidaqmx")
    except ImportError:
        raise DeviceError(device, "open", "the nidaqmx package is not installed (pip install 'labctl[hw]')") from None


def ni_error(device: str, action: str, exc: Exception) -> DeviceError:
    """A DAQmx error as the typed error, keeping NI's code and message."""
    code = getattr(exc, "error_code", None)
    text = " ".join(str(exc).split())[:300]
    if code in TIMEOUT_CODES:
        return DeviceTimeout(device, action, f"DAQmx {code}: {text}")
    if code in BUSY_CODES:
        return DeviceBusy(device, action, f"in use by another task (DAQmx {code})")
    if code in GONE_CODES:
        return DeviceDisconnected(device, action, f"{GONE_CODES[code]} (DAQmx {code}): {text}")
    if code == UNREACHABLE_CODE:
        return DeviceDisconnected(device, action, f"could not read a network device's properties (DAQmx {code}): "
                                  f"is the Ethernet cDAQ chassis powered and reachable? {text}")
    if type(exc).__name__ == "DaqNotFoundError":
        return DeviceError(device, action, "the NI-DAQmx driver is not installed on this computer")
    return DeviceError(device, action, f"DAQmx {code}: {text}" if code is not None else text)


class NiDaq(Lifecycle):
    """A finite, reference-triggered acquisition of every wired channel; ``configure`` returns the real rate."""

    def __init__(self, wiring: Sequence[InputWiring], *, iepe_current_a: float = 0.002, name: str = "daq@nidaqmx",
                 nidaqmx_module: ModuleType | Any = None, module_type: str | None = None) -> None:
        self.name = name
        self.module_type = module_type  # the product every device of the wiring must be (``None``: not checked)
        self._force_row, _ = check_wiring(name, wiring)
        self._wiring = tuple(wiring)
        self.iepe_current_a = iepe_current_a
        self._ni = nidaqmx_module
        self._task: Any = None
        self._rate_hz = 0.0
        self._n_samples = 0
        self._pretrigger: int | None = None  # set by arm, cleared by acquire
        self.requested_rate_hz = 0.0
        self.record_s = 0.0

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


    @property
    def n_samples(self) -> int:
        """Samples per record at the device's rate (``record_s`` × the rate read back)."""
        return self._n_samples

    def configure(self, sample_rate_hz: float, n_samples: int) -> float:
        """Create the task for ``n_samples / sample_rate_hz`` seconds; return the sample clock read back.

        An NI 9234 runs at 51.2 kS/s ÷ n only, so the rate it sets differs from most requests; the sample count is
        then recomputed so the record keeps its duration.
        """
        if n_samples < 2 or not sample_rate_hz > 0:
            raise ValueError(f"{self.name}: {n_samples!r} samples at {sample_rate_hz!r} Hz: expected a positive "
                             "rate and at least 2 samples")
        ni = self._module()
        self.close()
        self.requested_rate_hz = float(sample_rate_hz)
        self.record_s = n_samples / self.requested_rate_hz
        finite = ni.constants.AcquisitionType.FINITE
        with self._errors("configure"):
            self._task = ni.Task()
            for w in self._wiring:
                self._add_channel(ni, w)
            self._task.timing.cfg_samp_clk_timing(sample_rate_hz, sample_mode=finite, samps_per_chan=int(n_samples))
            self._rate_hz = float(self._task.timing.samp_clk_rate)
            self._n_samples = samples_at_rate(n_samples, self.requested_rate_hz, self._rate_hz)
            if self._n_samples != n_samples:
                self._task.timing.cfg_samp_clk_timing(sample_rate_hz, sample_mode=finite,
                                                      samps_per_chan=self._n_samples)
                self._rate_hz = float(self._task.timing.samp_clk_rate)
        return self._rate_hz

    def pretrigger_at_rate(self, pretrigger_samples: int) -> int:
        """The pretrigger asked for at the requested rate, as samples at the device's rate (same duration)."""
        return samples_at_rate(pretrigger_samples, self.requested_rate_hz, self._rate_hz) if pretrigger_samples \
            else 0

    def arm(self, trigger: TriggerSpec) -> None:
        """Reference trigger on the force channel rising through ``level_n``, keeping the pretrigger's duration.

        The trigger source is the force channel's virtual channel name, as DAQmx documents for an analog edge
        reference trigger (a virtual channel of the task or a terminal).
        """
        if self._task is None:
            raise DeviceError(self.name, "arm", "configure() first")
        pretrigger = self.pretrigger_at_rate(trigger.pretrigger_samples)
        if not 0 <= pretrigger < self._n_samples:
            raise ValueError(f"{self.name}: pretrigger {trigger.pretrigger_samples} samples at "
                             f"{self.requested_rate_hz:g} Hz = {pretrigger} at {self._rate_hz:g} Hz: expected fewer "
                             f"than the record's {self._n_samples}")
        ni = self._module()
        force = self._wiring[self._force_row]
        with self._errors("arm"):
            self._task.stop()
            self._task.triggers.reference_trigger.cfg_anlg_edge_ref_trig(
                force.channel.name, pretrigger_samples=pretrigger,
                trigger_slope=ni.constants.Slope.RISING, trigger_level=trigger.level_n)
            self._task.start()
        self._pretrigger = pretrigger

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
            present = {d.name: d for d in system.devices}
        missing = [d for d in devices if d not in present]
        if missing:
            raise DeviceDisconnected(self.name, "probe", f"not present: {', '.join(missing)} "
                                     f"(present: {', '.join(sorted(present)) or 'none'})")
        if self.module_type is not None:
            with self._errors("probe"):
                products = {d: str(present[d].product_type) for d in devices}
            wrong = [f"{d} is an {p}" for d, p in products.items() if p != self.module_type]
            if wrong:
                raise DeviceError(self.name, "probe", f"{'; '.join(wrong)}, not the {self.module_type} of the "
                                  "devices file (daq.module)")
        kind = f"{self.module_type} " if self.module_type else ""
        return f"NI-DAQmx {kind}devices {', '.join(devices)} present, {len(self._wiring)} channels"

    def _add_channel(self, ni: Any, w: InputWiring) -> None:
        """An IEPE channel with internal excitation, explicitly AC coupled (no IEPE current in DC-coupled mode)."""
        c, k = w.channel, ni.constants
        common = dict(name_to_assign_to_channel=c.name, min_val=-c.range_units, max_val=c.range_units,
                      current_excit_source=k.ExcitationSource.INTERNAL, current_excit_val=self.iepe_current_a)
        if c.kind == "force":
            chan = self._task.ai_channels.add_ai_force_iepe_chan(
                w.terminal, units=k.ForceUnits.NEWTONS, sensitivity=c.sensitivity_v_per_unit * 1e3,
                sensitivity_units=k.ForceIEPESensorSensitivityUnits.MILLIVOLTS_PER_NEWTON, **common)
        else:
            mv_per_g = c.sensitivity_v_per_unit * 1e3 * STANDARD_GRAVITY_M_PER_S2
            chan = self._task.ai_channels.add_ai_accel_chan(
                w.terminal, units=k.AccelUnits.METERS_PER_SECOND_SQUARED, sensitivity=mv_per_g,
                sensitivity_units=k.AccelSensitivityUnits.MILLIVOLTS_PER_G, **common)
        chan.ai_coupling = k.Coupling.AC

    def settings_report(self) -> list[Finding]:
        """The task's settings as DAQmx reads them back: sample clock, and per channel range, coupling, IEPE."""
        if self._task is None:
            return [Finding("daq", "settings", "no task", FAILED, "configure() first")]
        rows: list[Finding] = []
        with self._errors("check"):
            rate = float(self._task.timing.samp_clk_rate)
            rows.append(Finding("daq", "sample rate", f"{rate:.6g} Hz", VERIFIED,
                                f"read back from DAQmx; asked {self.requested_rate_hz:g} Hz"))
            for ch in self._task.ai_channels:
                try:
                    low, high = float(ch.ai_min), float(ch.ai_max)
                    coupling, current = ch.ai_coupling.name, float(ch.ai_excit_val)
                    source = ch.ai_excit_src.name
                except AttributeError as exc:
                    rows.append(Finding(ch.name, "settings", "not readable", NOT_VERIFIED, str(exc)))
                    continue
                rows.append(Finding(ch.name, "input range", f"{low:g} … {high:g}", VERIFIED, "read back"))
                rows.append(Finding(ch.name, "coupling", coupling, VERIFIED if coupling == "AC" else FAILED,
                                    "read back" if coupling == "AC" else "IEPE current needs AC coupling"))
                powered = source == "INTERNAL" and current > 0
                rows.append(Finding(ch.name, "IEPE current", f"{current * 1e3:g} mA ({source.lower()})",
                                    VERIFIED if powered else FAILED, "set and read back; the sensor's draw is "
                                    "shown by its response row" if powered else "no excitation"))
        return rows

    def coupling(self) -> dict[str, str]:
        """Each channel's coupling as the task reports it (``AC``/``DC``), for ``devices check --acquire``."""
        if self._task is None:
            return {}
        with self._errors("check"):
            return {ch.name: ch.ai_coupling.name for ch in self._task.ai_channels}

    def _overloaded(self) -> list[str]:
        """Channels the device reports overloaded; none when it cannot say (values at the channel's range are
        still flagged by ``make_record``)."""
        stream = self._task.in_stream
        try:
            return list(stream.overloaded_chans) if stream.overloaded_chans_exist else []
        except (self._module().errors.Error, AttributeError):  # a device (or stand-in) without overload status
            return []

    def _module(self) -> Any:
        if self._ni is None:
            self._ni = import_nidaqmx(self.name)
        return self._ni

    @contextlib.contextmanager
    def _errors(self, action: str) -> Iterator[None]:
        """Turn DAQmx exceptions raised inside the block into typed device errors."""
        daqmx_error = self._module().errors.Error
        try:
            yield
        except daqmx_error as exc:
            raise ni_error(self.name, action, exc) from exc
