"""The real rig from a devices file: which load cell, DAQ, hammer and knob actuator, and how they are wired.

The devices file is TOML with units at its edge (mV/N, mV/g, N, g, s); see ``labctl/data/devices.example.toml``.
``make_hw_rig`` builds a ``drivers.Rig`` (``labctl.backends`` calls it for ``--backend hw``); ``check_devices``
opens and probes each configured instrument and says plainly what works and what does not; ``tap_check_devices``
takes one triggered record of a light tap and tabulates what it verified.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import tomllib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from drivers.errors import DeviceError
from drivers.hw import InputWiring, ManualActuator, ManualHammer, MccUsbDaq, MtSicsLoadCell, NiDaq, SerialHammer
from drivers.hw.serial_line import HANDSHAKES, parse_serial_format
from drivers.hw.verify import FAILED, NOT_VERIFIED, Finding, TapSettings, tap_check
from drivers.interfaces import Channel, Operator, Rig
from labctl.data import data_path, read_toml
from labctl.data.schema import Integer, Number, Spec, Table, Tables, Text, Where, check_keys, read, value
from labctl.data.units import MV, STANDARD_GRAVITY_M_PER_S2
from labctl.errors import InputError, LabctlError
from labctl.physics.rig_config import RigConfig

DEVICES_ENV = "LABCTL_DEVICES"
SECTIONS = ("load_cell", "daq", "hammer", "actuator")
OPTIONAL_SECTIONS = ("displacement",)  # the static method's sensor (docs/static.md)
ABSENT_OK = ("load_cell",)  # a rig without one runs load_source = "springs" campaigns only


class AbsentLoadCell:
    """The load cell of a devices file without ``[load_cell]``: using it is a clear error, never a reading."""

    name = "no load cell"

    def _absent(self, *_: object) -> Any:
        raise DeviceError(self.name, "use", "the devices file has no [load_cell]: only protocols with "
                          "[loading] load_source = \"springs\" can run on this rig")

    open = close = probe = read = tare = _absent

    def __enter__(self) -> AbsentLoadCell:
        return self._absent()

    def __exit__(self, *exc: object) -> None:
        return None
ACCEL_NAME = re.compile(r"^A[1-4][XYZ]$")  # docs/contracts.md: A1-A3 above rollers 1-3, A4 bottom centre; X, Y, Z
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
    """Parse and validate a devices file into one spec per role; errors name the file, table, key and value.

    ``usb_backend`` (a pyusb backend) and ``nidaqmx_module`` replace the system's, e.g. with emulators.
    """
    path = find_devices_file(devices)
    top = Where(str(path))
    doc = read_toml(path)
    check_keys(doc, SECTIONS + OPTIONAL_SECTIONS, top)
    missing = [s for s in SECTIONS if s not in doc and s not in ABSENT_OK]
    if missing:
        raise top.problem(f"missing section(s) [{'], ['.join(missing)}]; see {EXAMPLE}")
    tables = read(doc, {s: Table(default=None) if s in ABSENT_OK else Table() for s in SECTIONS}, top,
                  unknown_ok=True)
    specs = {
        "load_cell": (_load_cell(tables["load_cell"], top.at("load_cell")) if tables.get("load_cell") is not None
                      else DeviceSpec("load_cell", "none", "", lambda _op: AbsentLoadCell())),
        "daq": _daq(tables["daq"], top.at("daq"), usb_backend, nidaqmx_module),
        "hammer": _hammer(tables["hammer"], top.at("hammer")),
        "actuator": _actuator(tables["actuator"], top.at("actuator")),
    }
    if "displacement" in doc:
        where = top.at("displacement")
        specs["displacement"] = _displacement(value(doc, "displacement", Table(), top), where, usb_backend,
                                              nidaqmx_module)
    return specs


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
               operator=operator, backend="hw", description=description, displacement=built.get("displacement"))


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


def tap_check_devices(devices: str | Path | None, operator: Operator, settings: TapSettings | None = None, *,
                      usb_backend: Any = None, nidaqmx_module: Any = None) -> list[Finding]:
    """The first-day check: open the DAQ, hammer and load cell, take one triggered record of a light tap and
    read the load cell; the table of what was verified and what was not. A device failure is a FAILED row."""
    settings = settings or TapSettings()
    rig = make_hw_rig(devices, operator, usb_backend=usb_backend, nidaqmx_module=nidaqmx_module)
    unverifiable = []
    if isinstance(rig.daq, MccUsbDaq) and rig.daq.conditioner:
        unverifiable.append(Finding("daq", "conditioner gain", rig.daq.conditioner, NOT_VERIFIED,
                                    "part of every sensitivity: check it against the conditioner's front panel"))
    try:
        with contextlib.ExitStack() as stack:
            for instrument in (rig.daq, rig.hammer, rig.load_cell):
                stack.enter_context(instrument)
            operator.notify("First-day check: when asked to strike, tap the upper disc LIGHTLY with the hammer "
                            f"(above {settings.trigger_level_n:g} N, well below the channels' ranges)")
            return tap_check(rig.daq, rig.hammer, rig.load_cell, settings, unverifiable=unverifiable)
    except (DeviceError, ValueError) as exc:
        return [Finding("daq", "test record", "none", FAILED, str(exc))]


# ---- sections ----------------------------------------------------------------------------------------------
LOAD_CELL: dict[str, Spec] = {
    "type": Text(("mtsics",)), "port": Text(), "baudrate": Integer(ge=1, default=9600),
    "serial_format": Text(default="8N1"), "handshake": Text(HANDSHAKES, default="none"),
    "timeout_s": Number(gt=0, default=2.0), "busy_retries": Integer(ge=0, default=3),
    "stable_timeout_s": Number(gt=0, default=10.0), "gravity_m_per_s2": Number(gt=0, default=STANDARD_GRAVITY_M_PER_S2),
}
SERIAL_HAMMER: dict[str, Spec] = {
    "type": Text(("serial",)), "port": Text(), "level": Integer(1, 255, default=128),
    "baudrate": Integer(ge=1, default=115200), "timeout_s": Number(gt=0, default=2.0),
    "boot_delay_s": Number(ge=0, default=2.0),
}
ACTUATOR: dict[str, Spec] = {"type": Text(("manual",)), "knobs": Integer(ge=1, default=4)}


def _load_cell(t: dict[str, Any], where: Where) -> DeviceSpec:
    options = read(t, LOAD_CELL, where)
    try:
        parse_serial_format(options["serial_format"])
    except ValueError:
        raise where.bad("serial_format", options["serial_format"], "data bits 5-8, parity N/E/O/M/S, stop bits "
                        "1/1.5/2, e.g. '8N1' or '7E1'") from None
    kind, port = options.pop("type"), options.pop("port")
    return DeviceSpec("load_cell", kind, port, lambda _op: MtSicsLoadCell(port, **options))


MCC_INPUTS = 8  # USB-1608FS-Plus: 8 single-ended inputs, no IEPE current (docs/hardware.md, device facts)
NI_MODULE_INPUTS = {"NI 9234": 4}  # IEPE inputs per module (NI 9234: ai0-ai3, 2 mA IEPE, AC coupled)
NI_IEPE_CURRENT_A = {"NI 9234": 0.002}
NI_TERMINAL = re.compile(r"^([^/\s]+)/ai(\d+)$")
CONDITIONER: dict[str, Spec] = {"model": Text(), "gain": Number(gt=0, default=1.0)}


def too_many_for_one_mcc(n: int) -> str:
    """What a lab must add when a devices file puts more channels on one USB-1608FS-Plus than it has inputs."""
    modules = -(-n // NI_MODULE_INPUTS["NI 9234"])
    return (f"{n} channels on one USB-1608FS-Plus, which has {MCC_INPUTS} single-ended inputs and supplies no IEPE "
            f"current: for {n} IEPE channels use type = \"nidaqmx\" with {modules} × NI 9234 (4 IEPE inputs each), "
            f"or wire at most {MCC_INPUTS} (the force and {MCC_INPUTS - 1} accelerometers) through an IEPE signal "
            "conditioner declared in [daq.conditioner]; labctl does not run two units clocked through SYNC")


def _daq(t: dict[str, Any], where: Where, usb_backend: Any, nidaqmx_module: Any) -> DeviceSpec:
    kind = value(t, "type", Text(("mcc_usb", "nidaqmx")), where)
    extra: dict[str, Spec] = {"serial": Text(default=""), "conditioner": Table(default=None)} if kind == "mcc_usb" \
        else {"iepe_current_ma": Number(gt=0, unit="ma", default=2.0),
              "module": Text(tuple(NI_MODULE_INPUTS), default="NI 9234")}
    options = read(t, {"type": Text(), "channels": Tables(), **extra}, where)
    rows = options["channels"]
    if kind == "mcc_usb":
        if len(rows) > MCC_INPUTS:
            raise where.problem(too_many_for_one_mcc(len(rows)))
        conditioner = read(options["conditioner"], CONDITIONER, where.at("conditioner")) \
            if "conditioner" in options else None
        gain = conditioner["gain"] if conditioner else 1.0
        wiring = [_channel(row, where.at("channels").at(i), kind, gain) for i, row in enumerate(rows)]
        label = f"{conditioner['model']} (gain ×{gain:g})" if conditioner else ""
        serial = options["serial"] or None
        try:
            MccUsbDaq(wiring, serial=serial)  # validate the wiring now, with the file named
        except ValueError as exc:
            raise where.problem(str(exc)) from None
        return DeviceSpec("daq", kind, f"USB-1608FS-Plus {serial or '(first found)'}",
                          lambda _op: MccUsbDaq(wiring, serial=serial, backend=usb_backend, conditioner=label))
    module, current_a = options["module"], options["iepe_current_a"]
    supplied_ma = NI_IEPE_CURRENT_A[module] * 1e3
    if not math.isclose(current_a * 1e3, supplied_ma, rel_tol=1e-6):
        raise where.bad("iepe_current_ma", current_a * 1e3, f"{supplied_ma:g} (the {module} supplies {supplied_ma:g} "
                        "mA only)")
    wiring = [_channel(row, where.at("channels").at(i), kind) for i, row in enumerate(rows)]
    for i, w in enumerate(wiring):
        match = NI_TERMINAL.match(w.terminal)
        if not match or int(match.group(2)) >= NI_MODULE_INPUTS[module]:
            n = NI_MODULE_INPUTS[module]
            raise where.at("channels").at(i).bad(
                "input", w.terminal, f"'<module>/ai0' … '<module>/ai{n - 1}' (an {module} has {n} inputs: "
                f"{len(wiring)} channels need {-(-len(wiring) // n)} modules)")
    try:
        NiDaq(wiring, iepe_current_a=current_a)
    except ValueError as exc:
        raise where.problem(str(exc)) from None
    address = ", ".join(sorted({w.terminal.split("/")[0] for w in wiring}))
    return DeviceSpec("daq", kind, address, lambda _op: NiDaq(wiring, iepe_current_a=current_a, module_type=module,
                                                              nidaqmx_module=nidaqmx_module))


def _channel(row: dict[str, Any], where: Where, daq_kind: str, conditioner_gain: float = 1.0) -> InputWiring:
    """One input; the sensitivity at the DAQ input is the sensor's times the IEPE conditioner's gain (MCC)."""
    kind = value(row, "kind", Text(("force", "acceleration")), where)
    force = kind == "force"
    sens_key, range_key = ("sensitivity_mv_per_n", "range_n") if force else ("sensitivity_mv_per_g", "range_g")
    t = read(row, {"name": Text(), "kind": Text(), "input": Integer() if daq_kind == "mcc_usb" else Text(),
                   sens_key: Number(gt=0), range_key: Number(gt=0), "adc_range_v": Number(gt=0, default=None),
                   **({} if force else CROSS_AXIS)}, where)
    name = t["name"]
    if not force and not ACCEL_NAME.match(name):
        raise where.bad("name", name, "an accelerometer name A1X … A4Z")
    if "adc_range_v" in t and daq_kind != "mcc_usb":
        raise where.problem("adc_range_v: only for type = 'mcc_usb' (NI sets its range from range_*)")
    per_unit = 1.0 if force else STANDARD_GRAVITY_M_PER_S2  # mV/g -> V/(m/s²), g -> m/s²
    sensitivity = t[sens_key] * MV / per_unit * conditioner_gain
    channel = Channel(name, kind, "N" if force else "m/s^2", sensitivity, t[range_key] * per_unit)
    return InputWiring(channel, str(t["input"]), t.get("adc_range_v"))


# --- per-channel cross-axis coupling of the accelerometers (docs/processing.md, "Cross-axis coupling") ---------
CROSS_AXIS: dict[str, Spec] = {"transverse_sensitivity": Number(ge=0, le=0.5, default=None),
                               "mounting_angle_deg": Number(ge=0, le=30, unit="deg", default=None)}


def channel_cross_axis(doc: dict[str, Any], where: Where) -> dict[str, tuple[float | None, float | None]]:
    """Per accelerometer channel of a devices document: its transverse sensitivity and mounting angle (rad), each
    None where the document gives none (the rig file's value then holds)."""
    daq = doc.get("daq")
    rows = daq.get("channels", []) if isinstance(daq, dict) else []
    out: dict[str, tuple[float | None, float | None]] = {}
    for i, row in enumerate(rows if isinstance(rows, list) else []):
        t = read(row, CROSS_AXIS, where.at("daq").at("channels").at(i), unknown_ok=True)
        if "transverse_sensitivity" in t or "mounting_angle_rad" in t:
            out[str(row.get("name"))] = (t.get("transverse_sensitivity"), t.get("mounting_angle_rad"))
    return out


def rig_with_channel_cross_axis(rig: RigConfig, devices_text: str, source: str) -> RigConfig:
    """The rig with a devices file's per-channel values (its text; ``source`` names it in errors) in its sensors.
    The rig model holds one value per tri-axial sensor, so a sensor takes the largest given for its channels:
    its σ is never understated."""
    try:
        doc = tomllib.loads(devices_text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{source}: not valid TOML ({exc})") from None
    given = channel_cross_axis(doc, Where(source))
    if not given:
        return rig
    sensors = []
    for s in rig.sensors:
        ts = [t for c, (t, _) in given.items() if c in s.channels and t is not None]
        angles = [a for c, (_, a) in given.items() if c in s.channels and a is not None]
        sensors.append(replace(s, transverse_sensitivity=max(ts) if ts else s.transverse_sensitivity,
                               mounting_angle_rad=max(angles) if angles else s.mounting_angle_rad))
    return replace(rig, sensors=tuple(sensors))


DISPLACEMENT: dict[str, Spec] = {
    "type": Text(("nidaqmx", "mcc_usb")), "input": Text(), "sensitivity_um_per_v": Number(gt=0),
    "range_v": Number(gt=0, le=10, default=10.0), "window_ms": Number(gt=0, unit="ms", default=100.0),
    "sample_rate_hz": Number(gt=0, le=100e3, default=1000.0), "serial": Text(default=""),
}


def _displacement(t: dict[str, Any], where: Where, usb_backend: Any, nidaqmx_module: Any) -> DeviceSpec:
    """The static method's sensor: a conditioner's voltage on an NI terminal or an MCC input (``input = "3"``)."""
    from drivers.hw.displacement import DaqDisplacementSensor, MccVoltageWindow, NiVoltageWindow

    o = read(t, DISPLACEMENT, where)
    kind, terminal = o["type"], o["input"]

    def reader() -> Any:
        if kind == "nidaqmx":
            return NiVoltageWindow(terminal, range_v=o["range_v"], nidaqmx_module=nidaqmx_module)
        return MccVoltageWindow(int(terminal), range_v=o["range_v"], serial=o["serial"] or None, backend=usb_backend)

    try:
        reader()
    except ValueError as exc:
        raise where.problem(f"input = {terminal!r}: {exc}") from None
    return DeviceSpec("displacement", kind, terminal, lambda _op: DaqDisplacementSensor(
        reader(), sensitivity_um_per_v=o["sensitivity_um_per_v"], window_s=o["window_s"],
        sample_rate_hz=o["sample_rate_hz"]))


def _hammer(t: dict[str, Any], where: Where) -> DeviceSpec:
    kind = value(t, "type", Text(("manual", "serial")), where)
    if kind == "manual":
        read(t, {"type": Text()}, where)
        return DeviceSpec("hammer", kind, "operator", lambda op: ManualHammer(op))
    options = read(t, SERIAL_HAMMER, where)
    del options["type"]
    port = options.pop("port")
    return DeviceSpec("hammer", kind, port, lambda _op: SerialHammer(port, **options))


def _actuator(t: dict[str, Any], where: Where) -> DeviceSpec:
    knobs = read(t, ACTUATOR, where)["knobs"]
    return DeviceSpec("actuator", "manual", "operator", lambda op: ManualActuator(op, knobs=knobs))


def example_path() -> Path:
    return data_path("devices.example.toml")
