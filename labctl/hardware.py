"""The real rig from a devices file: which load cell, DAQ, hammer and knob actuator, and how they are wired.

The devices file is TOML with units at its edge (mV/N, mV/g, N, g, s); see ``labctl/data/devices.example.toml``.
``make_hw_rig`` builds a ``drivers.Rig`` (``labctl.backends`` calls it for ``--backend hw``); ``check_devices``
opens and probes each configured instrument and says plainly what works and what does not.
"""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drivers.errors import DeviceError
from drivers.hw import InputWiring, ManualActuator, ManualHammer, MccUsbDaq, MtSicsLoadCell, NiDaq, SerialHammer
from drivers.interfaces import Channel, Operator, Rig
from labctl.data import data_path, positive, read_toml, require
from labctl.errors import InputError, LabctlError

STANDARD_GRAVITY_M_PER_S2 = 9.80665
DEVICES_ENV = "LABCTL_DEVICES"
SECTIONS = ("load_cell", "daq", "hammer", "actuator")
ACCEL_NAME = re.compile(r"^A[1-4][XYZ]$")  # DESIGN §4: A1-A3 above rollers 1-3, A4 bottom centre; X, Y, Z
EXAMPLE = "the output of 'labctl devices example'"


class HardwareError(LabctlError):
    """An instrument failed while labctl talked to it directly (not inside a run): names device and cause."""


@contextlib.contextmanager
def hardware_errors() -> Iterator[None]:
    """Report a device failure inside the block as a one-line user error (the CLI exits 2 with it)."""
    try:
        yield
    except DeviceError as exc:
        raise HardwareError(str(exc)) from None


@dataclass(frozen=True)
class DeviceSpec:
    """One configured instrument: its role on the rig, its type, where it is, and how to build it."""

    role: str
    kind: str
    address: str
    build: Callable[[Operator], Any]


@dataclass(frozen=True)
class DeviceCheck:
    """What ``labctl devices check`` found for one instrument."""

    role: str
    kind: str
    address: str
    ok: bool
    detail: str

    def to_dict(self) -> dict[str, Any]:
        return {"role": self.role, "type": self.kind, "address": self.address, "ok": self.ok, "detail": self.detail}


def find_devices_file(devices: str | Path | None = None) -> Path:
    """The devices file: the one given, else ``$LABCTL_DEVICES``, ``./devices.toml``, ``~/.config/labctl/``."""
    if devices is not None:
        return Path(devices)
    candidates = [os.environ.get(DEVICES_ENV), "devices.toml", Path.home() / ".config" / "labctl" / "devices.toml"]
    for candidate in candidates:
        if candidate and Path(candidate).is_file():
            return Path(candidate)
    raise InputError(f"no devices file: pass --devices FILE, set {DEVICES_ENV}, or save {EXAMPLE} as ./devices.toml")


def load_devices(devices: str | Path | None = None, *, usb_backend: Any = None,
                 nidaqmx_module: Any = None) -> dict[str, DeviceSpec]:
    """Parse and validate a devices file into one spec per role; errors name the file, key and value.

    ``usb_backend`` (a pyusb backend) and ``nidaqmx_module`` replace the system's, e.g. with emulators.
    """
    path = find_devices_file(devices)
    doc = read_toml(path)
    _known(doc, SECTIONS, str(path))
    missing = [s for s in SECTIONS if s not in doc]
    if missing:
        raise InputError(f"{path}: missing section(s) [{'], ['.join(missing)}]; see {EXAMPLE}")
    tables = {s: require(doc, s, dict, str(path)) for s in SECTIONS}
    return {
        "load_cell": _load_cell(tables["load_cell"], f"{path}: load_cell"),
        "daq": _daq(tables["daq"], f"{path}: daq", usb_backend, nidaqmx_module),
        "hammer": _hammer(tables["hammer"], f"{path}: hammer"),
        "actuator": _actuator(tables["actuator"], f"{path}: actuator"),
    }


def make_hw_rig(devices: str | Path | None, operator: Operator | None = None, *, usb_backend: Any = None,
                nidaqmx_module: Any = None) -> Rig:
    """The real instruments of the devices file as a ``drivers.Rig`` (opened by the engine, not here)."""
    specs = load_devices(devices, usb_backend=usb_backend, nidaqmx_module=nidaqmx_module)
    if operator is None:
        from drivers.operators import ConsoleOperator

        operator = ConsoleOperator()
    built = {role: spec.build(operator) for role, spec in specs.items()}
    description = {"devices": str(find_devices_file(devices)),
                   **{role: f"{spec.kind} {spec.address}" for role, spec in specs.items()}}
    return Rig(daq=built["daq"], hammer=built["hammer"], load_cell=built["load_cell"], actuator=built["actuator"],
               operator=operator, backend="hw", description=description)


def check_devices(devices: str | Path | None = None, *, usb_backend: Any = None,
                  nidaqmx_module: Any = None) -> list[DeviceCheck]:
    """Open and probe every configured instrument; one result per role, failures included, never raised."""
    from drivers.operators import ScriptedOperator

    specs = load_devices(devices, usb_backend=usb_backend, nidaqmx_module=nidaqmx_module)
    results = []
    for role, spec in specs.items():
        instrument = None
        try:
            instrument = spec.build(ScriptedOperator())
            instrument.open()
            ok, detail = True, instrument.probe()
        except (DeviceError, ValueError, OSError) as exc:
            ok, detail = False, str(exc)
        finally:
            if instrument is not None:
                with contextlib.suppress(DeviceError):
                    instrument.close()
        results.append(DeviceCheck(role, spec.kind, spec.address, ok, detail))
    return results


# ---- sections ----------------------------------------------------------------------------------------------
def _load_cell(t: dict[str, Any], where: str) -> DeviceSpec:
    kind = _choice(t, "type", ("mtsics",), where)
    _known(t, ("type", "port", "baudrate", "timeout_s", "busy_retries", "stable_timeout_s", "gravity_m_per_s2"),
           where)
    port = require(t, "port", str, where)
    options = dict(baudrate=_int(t, "baudrate", 9600, where), timeout_s=_pos(t, "timeout_s", 2.0, where),
                   busy_retries=_int(t, "busy_retries", 3, where, low=0),
                   stable_timeout_s=_pos(t, "stable_timeout_s", 10.0, where),
                   gravity_m_per_s2=_pos(t, "gravity_m_per_s2", STANDARD_GRAVITY_M_PER_S2, where))
    return DeviceSpec("load_cell", kind, port, lambda _op: MtSicsLoadCell(port, **options))


def _daq(t: dict[str, Any], where: str, usb_backend: Any, nidaqmx_module: Any) -> DeviceSpec:
    kind = _choice(t, "type", ("mcc_usb", "nidaqmx"), where)
    extra = ("serial",) if kind == "mcc_usb" else ("iepe_current_ma",)
    _known(t, ("type", "channels", *extra), where)
    rows = require(t, "channels", list, where)
    wiring = [_channel(row, f"{where}.channels[{i}]", kind) for i, row in enumerate(rows)]
    try:
        if kind == "mcc_usb":
            serial = require(t, "serial", str, where) if t.get("serial") else None
            MccUsbDaq(wiring, serial=serial)  # validate the wiring now, with the file named
            return DeviceSpec("daq", kind, f"USB-1608FS-Plus {serial or '(first found)'}",
                              lambda _op: MccUsbDaq(wiring, serial=serial, backend=usb_backend))
        current_a = _pos(t, "iepe_current_ma", 2.0, where) * 1e-3
        NiDaq(wiring, iepe_current_a=current_a)
    except ValueError as exc:
        raise InputError(f"{where}: {exc}") from None
    address = ", ".join(sorted({w.terminal.split("/")[0] for w in wiring}))
    return DeviceSpec("daq", kind, address,
                      lambda _op: NiDaq(wiring, iepe_current_a=current_a, nidaqmx_module=nidaqmx_module))


def _channel(row: Any, where: str, daq_kind: str) -> InputWiring:
    if not isinstance(row, dict):
        raise InputError(f"{where} = {row!r}: expected a table with name, kind, input, sensitivity and range")
    kind = _choice(row, "kind", ("force", "acceleration"), where)
    unit, sens_key, range_key = ("n", "sensitivity_mv_per_n", "range_n") if kind == "force" else \
        ("g", "sensitivity_mv_per_g", "range_g")
    _known(row, ("name", "kind", "input", sens_key, range_key, "adc_range_v"), where)
    name = require(row, "name", str, where)
    if kind == "acceleration" and not ACCEL_NAME.match(name):
        raise InputError(f"{where}.name = {name!r}: expected an accelerometer name A1X … A4Z")
    terminal = require(row, "input", int if daq_kind == "mcc_usb" else str, where)
    per_unit = 1.0 if unit == "n" else STANDARD_GRAVITY_M_PER_S2  # V/g -> V/(m/s²)
    channel = Channel(name, kind, "N" if unit == "n" else "m/s^2",
                      positive(row, sens_key, where) * 1e-3 / per_unit, positive(row, range_key, where) * per_unit)
    adc = positive(row, "adc_range_v", where) if "adc_range_v" in row else None
    if adc is not None and daq_kind != "mcc_usb":
        raise InputError(f"{where}.adc_range_v: only for type = 'mcc_usb' (NI sets its range from range_*)")
    return InputWiring(channel, str(terminal), adc)


def _hammer(t: dict[str, Any], where: str) -> DeviceSpec:
    kind = _choice(t, "type", ("manual", "serial"), where)
    if kind == "manual":
        _known(t, ("type",), where)
        return DeviceSpec("hammer", kind, "operator", lambda op: ManualHammer(op))
    _known(t, ("type", "port", "level", "baudrate", "timeout_s", "boot_delay_s"), where)
    port = require(t, "port", str, where)
    options = dict(level=_int(t, "level", 128, where, low=1, high=255), baudrate=_int(t, "baudrate", 115200, where),
                   timeout_s=_pos(t, "timeout_s", 2.0, where), boot_delay_s=_num(t, "boot_delay_s", 2.0, where))
    return DeviceSpec("hammer", kind, port, lambda _op: SerialHammer(port, **options))


def _actuator(t: dict[str, Any], where: str) -> DeviceSpec:
    _choice(t, "type", ("manual",), where)
    _known(t, ("type", "knobs"), where)
    knobs = _int(t, "knobs", 4, where, low=1)
    return DeviceSpec("actuator", "manual", "operator", lambda op: ManualActuator(op, knobs=knobs))


# ---- value helpers -----------------------------------------------------------------------------------------
def _known(table: dict[str, Any], allowed: tuple[str, ...], where: str) -> None:
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise InputError(f"{where}: unknown key(s) {', '.join(unknown)}; expected {', '.join(allowed)}")


def _choice(table: dict[str, Any], key: str, options: tuple[str, ...], where: str) -> str:
    value = require(table, key, str, where)
    if value not in options:
        raise InputError(f"{where}.{key} = {value!r}: expected one of {', '.join(options)}")
    return value


def _int(table: dict[str, Any], key: str, default: int, where: str, *, low: int = 1, high: int | None = None) -> int:
    value = require(table, key, int, where) if key in table else default
    if value < low or (high is not None and value > high):
        bounds = f"{low}-{high}" if high is not None else f"at least {low}"
        raise InputError(f"{where}.{key} = {value!r}: expected an integer {bounds}")
    return value


def _pos(table: dict[str, Any], key: str, default: float, where: str) -> float:
    return positive(table, key, where) if key in table else default


def _num(table: dict[str, Any], key: str, default: float, where: str) -> float:
    value = require(table, key, float, where) if key in table else default
    if value < 0:
        raise InputError(f"{where}.{key} = {value!r}: expected zero or more")
    return value


def example_path() -> Path:
    return data_path("devices.example.toml")
