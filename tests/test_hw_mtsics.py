"""MT-SICS load cell driver against a pseudo-terminal emulator: exact exchanges, statuses, units, failures."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest
import serial

from drivers.errors import DeviceBusy, DeviceDisconnected, DeviceError, DeviceTimeout
from drivers.hw.mtsics import MtSicsLoadCell, parse_reply, to_newton
from drivers.interfaces import LoadCell, LoadReading
from tests.emulators.instruments import MtSicsDevice
from tests.emulators.pty_serial import ExpectedProtocol, Pause, PtySerialEmulator

pytestmark = pytest.mark.waits  # on an emulated balance on a pseudo-terminal, in real time (tests/conftest.py)


@contextmanager
def exchange(pairs: list[tuple[str, Any]], **options: Any) -> Iterator[MtSicsLoadCell]:
    """A load cell on a pty whose emulator expects exactly ``pairs``; asserts all were consumed."""
    protocol = ExpectedProtocol(pairs)
    options.setdefault("timeout_s", 1.0)
    options.setdefault("retry_delay_s", 0.01)
    with PtySerialEmulator(protocol) as emulator, MtSicsLoadCell(emulator.port, **options) as cell:
        yield cell
    protocol.assert_consumed()


def test_satisfies_the_load_cell_interface() -> None:
    assert isinstance(MtSicsLoadCell("/dev/null"), LoadCell)


@pytest.mark.parametrize(("reply", "force_n", "stable"), [
    ("S S      123.45 N", 123.45, True),
    ("S D       12.00 N", 12.0, False),
    ("S S      -3.50 N", -3.5, True),
    ("S S       1.000 kg", 9.80665, True),
    ("S S       0.250 kN", 250.0, True),
    ("S S     500.0 g", 4.903325, True),
])
def test_read_parses_right_justified_values_and_converts_units(reply: str, force_n: float, stable: bool) -> None:
    with exchange([("SI", reply)]) as cell:
        reading = cell.read()
    assert reading == LoadReading(force_n=pytest.approx(force_n, rel=1e-12), stable=stable)


def test_zero_tare_clear_identify_reset_exchange() -> None:
    pairs = [("Z", "Z A"), ("T", "T S      10.00 N"), ("TAC", "TAC A"), ("I4", 'I4 A "B947123456"'),
             ("@", 'I4 A "B947123456"'), ("S", "S S 11.00 N")]
    with exchange(pairs) as cell:
        cell.zero()
        cell.tare()
        cell.clear_tare()
        assert cell.identify() == "B947123456"
        assert cell.reset() == "B947123456"
        assert cell.read_stable() == LoadReading(11.0, True)


def test_busy_is_retried_then_succeeds() -> None:
    with exchange([("SI", "S I"), ("SI", "S I"), ("SI", "S S 5.00 N")], busy_retries=3) as cell:
        assert cell.read().force_n == 5.0


def test_busy_every_time_reports_busy_after_the_retries() -> None:
    with exchange([("SI", "S I")] * 4, busy_retries=3) as cell, pytest.raises(DeviceBusy) as err:
        cell.read()
    assert "'SI'" in str(err.value) and "4 times" in str(err.value)
    assert err.value.device == cell.name and cell.port in err.value.device


@pytest.mark.parametrize(("command", "method", "reply", "fragment"), [
    ("SI", "read", "ES", "syntax error"),
    ("T", "tare", "EL", "logical error"),
    ("Z", "zero", "Z +", "overload"),
    ("SI", "read", "S +", "overload"),
    ("SI", "read", "S -", "underload"),
])
def test_error_and_range_codes_name_the_command(command: str, method: str, reply: str, fragment: str) -> None:
    with exchange([(command, reply)]) as cell, pytest.raises(DeviceError) as err:
        getattr(cell, method)()
    assert f"'{command}'" in str(err.value) and fragment in str(err.value)
    assert not isinstance(err.value, DeviceBusy | DeviceTimeout)


def test_transmission_error_is_sent_once_more() -> None:
    with exchange([("SI", "ET"), ("SI", "S S 1.00 N")]) as cell:
        assert cell.read().force_n == 1.0


def test_no_answer_times_out_within_the_configured_time() -> None:
    with exchange([("SI", None)], timeout_s=0.3) as cell:
        start = time.monotonic()
        with pytest.raises(DeviceTimeout) as err:
            cell.read()
        elapsed = time.monotonic() - start
    assert 0.3 <= elapsed < 0.6
    assert "no reply within 0.3 s" in str(err.value)


def test_a_reply_split_over_several_writes_is_reassembled() -> None:
    reply = [b"S S  ", Pause(0.05), b"    42.0", Pause(0.05), b"0 N\r", Pause(0.05), b"\n"]
    with exchange([("SI", reply)]) as cell:
        assert cell.read().force_n == 42.0


def test_a_partial_line_is_reported_as_such() -> None:
    with exchange([("SI", b"S S   4")], timeout_s=0.2) as cell, pytest.raises(DeviceTimeout) as err:
        cell.read()
    assert "partial reply" in str(err.value) and "S S   4" in str(err.value)


def test_garbage_and_stale_lines_are_skipped() -> None:
    reply = [b"\xff\x00\x13noise\r\n", "T S 3.00 N", "S S 7.00 N"]
    with exchange([("SI", reply)]) as cell:
        assert cell.read().force_n == 7.0


def test_only_garbage_is_a_timeout_that_shows_it() -> None:
    with exchange([("SI", b"\xfe\xfe##\r\n")], timeout_s=0.2) as cell, pytest.raises(DeviceTimeout) as err:
        cell.read()
    assert "no valid reply" in str(err.value)


def test_missing_port_is_disconnected() -> None:
    with pytest.raises(DeviceDisconnected) as err:
        MtSicsLoadCell("/dev/ttyNOSUCHPORT9").read()
    assert "/dev/ttyNOSUCHPORT9" in str(err.value) and "no such port" in str(err.value)


def test_port_held_by_another_program_is_busy() -> None:
    with PtySerialEmulator(MtSicsDevice(lambda: 1.0)) as emulator:
        holder = serial.Serial(emulator.port, exclusive=True)
        try:
            with pytest.raises(DeviceBusy) as err:
                MtSicsLoadCell(emulator.port).open()
        finally:
            holder.close()
    assert "in use" in str(err.value)


def test_permission_denied_is_explained(monkeypatch: pytest.MonkeyPatch) -> None:
    with PtySerialEmulator(MtSicsDevice(lambda: 1.0)) as emulator:
        real_open = os.open

        def refuse(path: str, *args: Any, **kw: Any) -> int:
            if path == emulator.port:
                raise PermissionError(13, "Permission denied", path)
            return real_open(path, *args, **kw)

        monkeypatch.setattr(os, "open", refuse)
        with pytest.raises(DeviceError) as err:
            MtSicsLoadCell(emulator.port).open()
        monkeypatch.undo()
    assert "permission denied" in str(err.value) and "dialout" in str(err.value)


def test_unplug_mid_session_is_disconnected() -> None:
    device = MtSicsDevice(lambda: 20.0)
    emulator = PtySerialEmulator(device).__enter__()
    with MtSicsLoadCell(emulator.port, timeout_s=0.5) as cell:
        assert cell.read().force_n == 20.0
        emulator.unplug()
        with pytest.raises(DeviceDisconnected) as err:
            cell.read()
    assert cell.port in str(err.value)


def test_port_failure_is_reopened_and_the_command_sent_again() -> None:
    device = MtSicsDevice(lambda: 30.0)
    with PtySerialEmulator(device) as emulator, MtSicsLoadCell(emulator.port) as cell:
        assert cell.read().force_n == 30.0
        broken = os.open(os.devnull, os.O_RDONLY)
        os.dup2(broken, cell._line._serial.fileno())  # the port's descriptor stops being a terminal
        os.close(broken)
        assert cell.read().force_n == 30.0
    assert device.log == ["SI", "SI"]


def test_behavioural_device_reports_through_the_driver() -> None:
    device = MtSicsDevice(lambda: 117.0, unit="kg", busy_replies=1)
    with PtySerialEmulator(device) as emulator, MtSicsLoadCell(emulator.port, retry_delay_s=0.01) as cell:
        assert cell.read().force_n == pytest.approx(117.0, abs=0.01)
        cell.tare()
        assert cell.read().force_n == pytest.approx(0.0, abs=0.01)
        assert "B947123456" in cell.probe()


def test_reply_parsing_and_units() -> None:
    assert parse_reply("S S      123.45 N").fields == ("123.45", "N")
    assert parse_reply("ES").head == "ES"
    assert parse_reply("\x00\x01") is None and parse_reply("S") is None
    assert to_newton(2.0, "lb") == pytest.approx(2 * 0.45359237 * 9.80665)
    with pytest.raises(ValueError, match="furlong"):
        to_newton(1.0, "furlong")


@pytest.mark.parametrize(("fmt", "handshake", "bits", "parity", "flow"), [
    ("7E1", "xonxoff", "CS7", "even", "IXON"),
    ("8N1", "none", "CS8", "none", ""),
    ("8O2", "rtscts", "CS8", "odd", "CRTSCTS"),
])
def test_serial_format_and_handshake_reach_the_port(fmt: str, handshake: str, bits: str, parity: str,
                                                    flow: str) -> None:
    """Weighing terminals are often set to 7E1 or XON/XOFF: the line is opened as configured. A Linux pty keeps
    the flow-control flags (read back with termios) but forces CS8 without parity, so the character format is
    checked on the opened port instead."""
    import termios

    with PtySerialEmulator(MtSicsDevice(lambda: 12.5)) as emulator, \
            MtSicsLoadCell(emulator.port, serial_format=fmt, handshake=handshake, timeout_s=1.0) as cell:
        assert cell.read().force_n == 12.5
        iflag, _, cflag, *_ = termios.tcgetattr(emulator._slave)
        port = cell._line._serial
        assert port is not None
        assert (port.bytesize, port.parity, port.stopbits) == (int(bits[2]), parity[0].upper(), int(fmt[2]))
    assert bool(iflag & termios.IXON) == (flow == "IXON")
    assert bool(cflag & termios.CRTSCTS) == (flow == "CRTSCTS")


@pytest.mark.parametrize(("fmt", "handshake", "fragment"), [("9N1", "none", "serial format '9N1'"),
                                                            ("8N1", "dtr", "handshake 'dtr'")])
def test_a_bad_serial_format_is_refused(fmt: str, handshake: str, fragment: str) -> None:
    with pytest.raises(ValueError, match=fragment):
        MtSicsLoadCell("/dev/null", serial_format=fmt, handshake=handshake)


def test_tare_on_a_level_0_device_says_tare_is_level_1() -> None:
    with exchange([("T", "ES")]) as cell, pytest.raises(DeviceError, match="'T' not understood.*level 1"):
        cell.tare()
