"""Devices file → drivers.Rig, its validation, and ``labctl devices check`` against emulated instruments."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from drivers.hw import ManualActuator, ManualHammer, MccUsbDaq, MtSicsLoadCell, NiDaq, SerialHammer
from drivers.operators import ScriptedOperator
from labctl.backends import make_rig
from labctl.errors import InputError
from labctl.hardware import check_devices, example_path, load_devices, make_hw_rig
from labctl.physics import ContactCase, material, roller
from tests.cli_util import assert_one_line_error, labctl
from tests.emulators.fake_nidaqmx import FakeNiHardware
from tests.emulators.fake_usb import FakeMcc1608, FakeUsbBackend
from tests.emulators.instruments import HammerDevice, MtSicsDevice
from tests.emulators.pty_serial import PtySerialEmulator

G = 9.80665

NI_DAQ = """
[daq]
type = "nidaqmx"
iepe_current_ma = 2.0
[[daq.channels]]
name = "F"
kind = "force"
input = "cDAQ1Mod1/ai0"
sensitivity_mv_per_n = 0.23
range_n = 2200.0
[[daq.channels]]
name = "A4Z"
kind = "acceleration"
input = "cDAQ1Mod2/ai3"
sensitivity_mv_per_g = 100.0
range_g = 50.0
"""


def devices_file(tmp_path: Path, *, load_port: str = "/dev/ttyUSB0", hammer: str = 'type = "manual"',
                 daq: str | None = None, edit: tuple[str, str] | None = None) -> Path:
    """The shipped example with the load-cell port, the hammer, the DAQ section or one line replaced."""
    text = example_path().read_text(encoding="utf-8").replace('port = "/dev/ttyUSB0"', f'port = "{load_port}"')
    head, _, tail = text.partition("[hammer]")
    text = head + f"[hammer]\n{hammer}\n\n[actuator]\n" + tail.partition("[actuator]")[2]
    if daq is not None:
        head, _, rest = text.partition("[daq]")
        text = head + daq + "\n[hammer]" + rest.partition("[hammer]")[2]
    if edit is not None:
        assert edit[0] in text, edit[0]
        text = text.replace(edit[0], edit[1], 1)
    path = tmp_path / "devices.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_example_file_builds_the_rig_in_si_units() -> None:
    operator = ScriptedOperator()
    rig = make_hw_rig(example_path(), operator=operator)
    assert rig.backend == "hw" and rig.operator is operator
    assert isinstance(rig.load_cell, MtSicsLoadCell) and rig.load_cell.port == "/dev/ttyUSB0"
    assert isinstance(rig.daq, MccUsbDaq) and isinstance(rig.hammer, ManualHammer)
    assert isinstance(rig.actuator, ManualActuator) and rig.actuator.knobs == 4
    channels = {c.name: c for c in rig.daq.channels}
    assert list(channels) == ["F", "A1Z", "A2Z", "A3Z", "A4Z", "A1X", "A2X", "A3X"]
    assert channels["F"].sensitivity_v_per_unit == pytest.approx(0.23e-3)
    assert channels["A1Z"].sensitivity_v_per_unit == pytest.approx(0.1 / G)
    assert channels["A1Z"].range_units == pytest.approx(50 * G, rel=1e-3)  # ±5 V range holds 50 g at 100 mV/g
    assert rig.description["daq"].startswith("mcc_usb") and rig.description["devices"] == str(example_path())


def test_serial_hammer_and_ni_daq_sections(tmp_path: Path) -> None:
    path = devices_file(tmp_path, hammer='type = "serial"\nport = "/dev/ttyACM0"\nlevel = 60\nboot_delay_s = 0',
                        daq=NI_DAQ)
    rig = make_hw_rig(path, operator=ScriptedOperator(), nidaqmx_module=FakeNiHardware().module())
    assert isinstance(rig.hammer, SerialHammer) and rig.hammer.level == 60
    assert isinstance(rig.daq, NiDaq) and rig.daq.iepe_current_a == pytest.approx(0.002)
    assert rig.description["daq"] == "nidaqmx cDAQ1Mod1, cDAQ1Mod2"


def test_backend_factory_hands_hw_to_the_devices_file() -> None:
    case = ContactCase(roller(1), material("1.3505"), 0.2e-6)
    rig = make_rig("hw", case=case, devices=example_path(), operator=ScriptedOperator())
    assert rig.backend == "hw" and isinstance(rig.daq, MccUsbDaq)


@pytest.mark.parametrize(("edit", "fragments"), [
    (('knobs = 4', 'knobs = 4\nspeed = 2'), ("actuator", "unknown key(s) speed")),
    (('type = "mcc_usb"', 'type = "usb-6009"'), ("daq.type = 'usb-6009'", "mcc_usb, nidaqmx")),
    (('name = "A2Z"', 'name = "A5Z"'), ("daq.channels[2].name = 'A5Z'", "A1X")),
    (('input = 7', 'input = 9'), ("daq:", "input '9'", "inputs 0-7")),
    (('input = 7', 'input = "ai7"'), ("daq.channels[7].input = 'ai7'", "expected int")),
    (('sensitivity_mv_per_n = 0.23', 'sensitivity_mv_per_n = -0.23'), ("sensitivity_mv_per_n = -0.23", "positive")),
    (('range_g = 50.0', 'range_mm = 50.0'), ("daq.channels[1]", "unknown key(s) range_mm")),
    (('port = "/dev/ttyUSB0"', 'port = 3'), ("load_cell.port = 3", "expected str")),
    (('busy_retries = 3', 'busy_retries = -1'), ("busy_retries = -1", "integer at least 0")),
    (('[actuator]', '[actuators]'), ("unknown key(s) actuators",)),
])
def test_bad_devices_files_name_file_key_and_value(tmp_path: Path, edit: tuple[str, str],
                                                   fragments: tuple[str, ...]) -> None:
    path = devices_file(tmp_path, edit=edit)
    with pytest.raises(InputError) as err:
        load_devices(path)
    for fragment in (str(path), *fragments):
        assert fragment in str(err.value)


def test_serial_hammer_level_out_of_range(tmp_path: Path) -> None:
    path = devices_file(tmp_path, hammer='type = "serial"\nport = "/dev/ttyACM0"\nlevel = 300')
    with pytest.raises(InputError, match=r"hammer.level = 300: expected an integer 1-255"):
        load_devices(path)


def test_check_with_every_instrument_answering(tmp_path: Path) -> None:
    with PtySerialEmulator(MtSicsDevice(lambda: 114.0)) as cell, PtySerialEmulator(HammerDevice()) as hammer:
        path = devices_file(tmp_path, load_port=cell.port,
                            hammer=f'type = "serial"\nport = "{hammer.port}"\nboot_delay_s = 0')
        checks = check_devices(path, usb_backend=FakeUsbBackend(FakeMcc1608(serial="01D2B3A4")))
    assert [c.role for c in checks] == ["load_cell", "daq", "hammer", "actuator"]
    assert all(c.ok for c in checks), checks
    detail = {c.role: c.detail for c in checks}
    assert "B947123456" in detail["load_cell"] and "114.00 N (stable)" in detail["load_cell"]
    assert "serial 01D2B3A4" in detail["daq"] and "AUTOHAMMER" in detail["hammer"]


def test_check_cli_reports_what_works_and_what_does_not(tmp_path: Path) -> None:
    with PtySerialEmulator(MtSicsDevice(lambda: 38.5)) as cell:
        path = devices_file(tmp_path, load_port=cell.port)
        proc = labctl("devices", "check", "--devices", str(path), "--json")
        text = labctl("devices", "check", "--devices", str(path))
    assert proc.returncode == 1, proc.stderr
    out = json.loads(proc.stdout)
    by_role = {d["role"]: d for d in out["devices"]}
    assert out["ok"] is False and out["devices_file"] == str(path)
    assert by_role["load_cell"]["ok"] and "38.50 N" in by_role["load_cell"]["detail"]
    assert not by_role["daq"]["ok"] and ("USB-1608FS-Plus" in by_role["daq"]["detail"]
                                         or "libusb" in by_role["daq"]["detail"])
    assert by_role["hammer"]["ok"] and by_role["actuator"]["ok"]
    assert "FAILED daq" in text.stdout and text.returncode == 1


def test_check_without_a_devices_file(tmp_path: Path) -> None:
    proc = labctl("devices", "check", cwd=str(tmp_path))
    assert_one_line_error(proc, "no devices file", "--devices")


def test_check_with_a_broken_devices_file(tmp_path: Path) -> None:
    path = devices_file(tmp_path, edit=('kind = "force"', 'kind = "pressure"'))
    assert_one_line_error(labctl("devices", "check", "--devices", str(path)), str(path), "kind = 'pressure'")


SERIAL_HAMMER = 'type = "serial"\nport = "/dev/ttyACM0"'


@pytest.mark.parametrize(("hammer", "edit", "message"), [
    ('type = "manual"', ("timeout_s = 2.0", "timeout_s = inf"),
     "load_cell.timeout_s = inf: expected a finite positive number"),
    ('type = "manual"', ("stable_timeout_s = 10.0", "stable_timeout_s = nan"),
     "load_cell.stable_timeout_s = nan: expected a finite positive number"),
    ('type = "manual"', ("range_g = 50.0", "range_g = inf"), "daq.channels[1].range_g = inf: expected a finite"),
    ('type = "manual"', ("sensitivity_mv_per_n = 0.23", "sensitivity_mv_per_n = nan"),
     "daq.channels[0].sensitivity_mv_per_n = nan: expected a finite positive number"),
    (SERIAL_HAMMER + "\nboot_delay_s = nan", None, "hammer.boot_delay_s = nan: expected a finite number ≥ 0"),
    (SERIAL_HAMMER + "\ntimeout_s = -inf", None, "hammer.timeout_s = -inf: expected a finite positive number"),
    ('type = "manual"', ("knobs = 4", "knobs = 4.0"), "actuator.knobs = 4.0: expected int (an integer at least 1)"),
    ('type = "manual"', ('name = "F"', "name = 5"), "daq.channels[0].name = 5: expected str (a string)"),
    ('type = "manual"', ("baudrate = 9600", "baudrat = 9600"),
     "load_cell: unknown key(s) baudrat (did you mean 'baudrate'?)"),
])
def test_nan_inf_and_garbage_in_a_devices_file_are_refused_naming_table_key_and_value(
        tmp_path: Path, hammer: str, edit: tuple[str, str] | None, message: str) -> None:
    path = devices_file(tmp_path, hammer=hammer, edit=edit)
    with pytest.raises(InputError) as err:
        load_devices(path)
    assert str(err.value).startswith(f"{path}: {message}"), str(err.value)


def test_ni_iepe_current_must_be_finite(tmp_path: Path) -> None:
    path = devices_file(tmp_path, daq=NI_DAQ.replace("iepe_current_ma = 2.0", "iepe_current_ma = inf"))
    with pytest.raises(InputError, match=r"daq\.iepe_current_ma = inf: expected a finite positive number"):
        load_devices(path, nidaqmx_module=FakeNiHardware().module())


def test_a_garbage_devices_file_is_one_line_naming_the_file(tmp_path: Path) -> None:
    path = tmp_path / "devices.toml"
    path.write_bytes(b"\x00\x01garbage = = [\n")
    with pytest.raises(InputError, match="not valid TOML"):
        load_devices(path)
    path.write_text('load_cell = 3\n[daq]\n[hammer]\n[actuator]\n')
    with pytest.raises(InputError, match=r"load_cell = 3: expected a table"):
        load_devices(path)


def test_a_bad_devices_file_is_refused_before_a_campaign_file_exists(tmp_path: Path) -> None:
    path = devices_file(tmp_path, edit=("sensitivity_mv_per_n = 0.23", "sensitivity_mv_per_n = nan"))
    out = tmp_path / "c.h5"
    proc = labctl("run", "protocols/quick_check.toml", "--backend", "hw", "--devices", str(path), "--out", str(out))
    assert_one_line_error(proc, str(path), "daq.channels[0].sensitivity_mv_per_n = nan")
    assert not out.exists()


PAPER_CHANNELS = ["F", *(f"A{i}{axis}" for i in range(1, 5) for axis in "XYZ")]  # the hammer + 4 tri-axial PCB 356A16


def daq_section(kind: str, names: list[str], extra: str = "") -> str:
    """A [daq] with ``names`` wired in order: MCC inputs 0, 1, …; NI four per module, cDAQ1Mod1/ai0 first."""
    rows = []
    for i, name in enumerate(names):
        where = str(i) if kind == "mcc_usb" else f'"cDAQ1Mod{i // 4 + 1}/ai{i % 4}"'
        sens = "sensitivity_mv_per_n = 0.23\nrange_n = 2200.0" if name == "F" else \
            "sensitivity_mv_per_g = 10.0\nrange_g = 50.0"
        rows.append(f'[[daq.channels]]\nname = "{name}"\nkind = "{"force" if name == "F" else "acceleration"}"\n'
                    f"input = {where}\n{sens}\n")
    return f'[daq]\ntype = "{kind}"\n{extra}\n' + "\n".join(rows)


def test_thirteen_channels_on_one_mcc_unit_are_refused_saying_what_to_add(tmp_path: Path) -> None:
    path = devices_file(tmp_path, daq=daq_section("mcc_usb", PAPER_CHANNELS))
    with pytest.raises(InputError) as err:
        load_devices(path)
    text = str(err.value)
    assert text.startswith(f"{path}: daq: 13 channels on one USB-1608FS-Plus, which has 8 single-ended inputs")
    for fragment in ("no IEPE current", 'type = "nidaqmx" with 4 × NI 9234', "[daq.conditioner]", "SYNC"):
        assert fragment in text
    assert "\n" not in text


def test_the_paper_rig_on_four_ni_9234_modules(tmp_path: Path) -> None:
    path = devices_file(tmp_path, daq=daq_section("nidaqmx", PAPER_CHANNELS))
    rig = make_hw_rig(path, operator=ScriptedOperator(), nidaqmx_module=FakeNiHardware().module())
    assert isinstance(rig.daq, NiDaq) and [c.name for c in rig.daq.channels] == PAPER_CHANNELS
    assert rig.description["daq"] == "nidaqmx cDAQ1Mod1, cDAQ1Mod2, cDAQ1Mod3, cDAQ1Mod4"
    assert rig.daq.module_type == "NI 9234"


@pytest.mark.parametrize(("old", "new", "message"), [
    ('"cDAQ1Mod2/ai3"', '"cDAQ1Mod2/ai4"', "daq.channels[1].input = 'cDAQ1Mod2/ai4': expected '<module>/ai0' … "
     "'<module>/ai3' (an NI 9234 has 4 inputs: 2 channels need 1 modules)"),
    ('"cDAQ1Mod2/ai3"', '"cDAQ1Mod2"', "daq.channels[1].input = 'cDAQ1Mod2': expected '<module>/ai0'"),
    ("iepe_current_ma = 2.0", "iepe_current_ma = 4.0",
     "daq.iepe_current_ma = 4.0: expected 2 (the NI 9234 supplies 2 mA only)"),
    ("iepe_current_ma = 2.0", 'module = "NI 9239"', "daq.module = 'NI 9239': expected one of NI 9234"),
])
def test_ni_channels_must_fit_the_modules(tmp_path: Path, old: str, new: str, message: str) -> None:
    path = devices_file(tmp_path, daq=NI_DAQ.replace(old, new))
    with pytest.raises(InputError) as err:
        load_devices(path, nidaqmx_module=FakeNiHardware().module())
    assert str(err.value).startswith(f"{path}: {message}"), str(err.value)


def test_the_iepe_conditioner_is_a_stage_of_the_sensitivity_chain(tmp_path: Path) -> None:
    """10 mV/g sensors behind a ×8 conditioner reach the DAQ at 80 mV/g: ±5 V holds the 50 g range (4 V)."""
    plain = devices_file(tmp_path, daq=daq_section("mcc_usb", PAPER_CHANNELS[:8]))
    daq = make_hw_rig(plain, operator=ScriptedOperator()).daq
    assert daq.input_ranges_v["A1X"] == 1.0 and daq.conditioner == ""  # 0.5 V full scale on ±1 V
    staged = devices_file(tmp_path, daq=daq_section("mcc_usb", PAPER_CHANNELS[:8],
                                                    '[daq.conditioner]\nmodel = "PCB 482C15"\ngain = 8.0\n'))
    daq = make_hw_rig(staged, operator=ScriptedOperator()).daq
    channels = {c.name: c for c in daq.channels}
    assert channels["A1X"].sensitivity_v_per_unit == pytest.approx(0.08 / G)  # 10 mV/g × 8
    assert channels["F"].sensitivity_v_per_unit == pytest.approx(0.23e-3 * 8)
    assert daq.input_ranges_v["A1X"] == 5.0 and daq.input_ranges_v["F"] == 5.0  # 4.05 V full scale on ±5 V
    assert daq.conditioner == "PCB 482C15 (gain ×8)"
    bad = devices_file(tmp_path, daq=daq_section("mcc_usb", ["F", "A1Z"], "[daq.conditioner]\ngain = 0\n"))
    with pytest.raises(InputError, match=r"daq.conditioner: missing key 'model'|daq.conditioner.gain = 0"):
        load_devices(bad)


def test_the_load_cells_serial_format_and_handshake(tmp_path: Path) -> None:
    path = devices_file(tmp_path, edit=("baudrate = 9600",
                                        'baudrate = 9600\nserial_format = "7E1"\nhandshake = "xonxoff"'))
    line = make_hw_rig(path, operator=ScriptedOperator()).load_cell._line
    assert (line.bytesize, line.parity, line.stopbits, line.handshake) == (7, "E", 1.0, "xonxoff")
    for edit, message in ((('baudrate = 9600', 'baudrate = 9600\nserial_format = "7X1"'),
                           "load_cell.serial_format = '7X1': expected data bits 5-8"),
                          (('baudrate = 9600', 'baudrate = 9600\nhandshake = "dtr"'),
                           "load_cell.handshake = 'dtr': expected one of none, xonxoff, rtscts")):
        with pytest.raises(InputError) as err:
            load_devices(devices_file(tmp_path, edit=edit))
        assert message in str(err.value)
