"""``labctl loadcell`` against an MT-SICS emulator on a pseudo-terminal (the issue's acceptance)."""

from __future__ import annotations

import json
import time

import pytest

from tests.cli_util import assert_one_line_error, labctl, labctl_json
from tests.emulators.instruments import MtSicsDevice
from tests.emulators.pty_serial import ExpectedProtocol, PtySerialEmulator

pytestmark = pytest.mark.waits  # on labctl subprocesses against an emulated balance (tests/conftest.py)

def test_read_prints_the_force_as_json() -> None:
    protocol = ExpectedProtocol([("SI", "S S      123.45 N")])
    with PtySerialEmulator(protocol) as emulator:
        out = labctl_json("loadcell", "read", "--port", emulator.port)
    protocol.assert_consumed()
    assert out["force_n"] == 123.45 and out["stable"] is True and out["port"] == emulator.port


def test_busy_is_retried_then_reported() -> None:
    protocol = ExpectedProtocol([("SI", "S I")] * 3)
    with PtySerialEmulator(protocol) as emulator:
        proc = labctl("loadcell", "read", "--port", emulator.port, "--retries", "2", "--json")
    protocol.assert_consumed()
    assert proc.stdout == ""
    assert_one_line_error(proc, emulator.port, "busy", "3 times")


def test_syntax_error_names_the_command() -> None:
    protocol = ExpectedProtocol([("SI", "ES")])
    with PtySerialEmulator(protocol) as emulator:
        proc = labctl("loadcell", "read", "--port", emulator.port, "--json")
    protocol.assert_consumed()
    assert_one_line_error(proc, emulator.port, "command 'SI'", "ES")


def test_silence_is_a_timeout_within_the_configured_time() -> None:
    protocol = ExpectedProtocol([("SI", None)])
    with PtySerialEmulator(protocol) as emulator:
        start = time.monotonic()
        proc = labctl("loadcell", "read", "--port", emulator.port, "--timeout", "0.5", "--json")
        elapsed = time.monotonic() - start
    protocol.assert_consumed()
    assert_one_line_error(proc, emulator.port, "no reply within 0.5 s")
    assert 0.5 <= elapsed < 0.5 + 5.0  # the rest is the interpreter starting


def test_missing_port_names_it() -> None:
    assert_one_line_error(labctl("loadcell", "read", "--port", "/dev/ttyNOSUCH7"), "/dev/ttyNOSUCH7", "no such port")


def test_bad_timeout_is_refused() -> None:
    assert_one_line_error(labctl("loadcell", "read", "--port", "/dev/null", "--timeout", "0"), "--timeout")


def test_tare_then_read_as_text() -> None:
    device = MtSicsDevice(lambda: 55.5)
    with PtySerialEmulator(device) as emulator:
        tare = labctl("loadcell", "tare", "--port", emulator.port, "--json")
        text = labctl("loadcell", "read", "--port", emulator.port)
    assert tare.returncode == 0 and json.loads(tare.stdout)["done"] == "tare"
    assert text.returncode == 0 and text.stdout.strip() == "0.00 N (stable)"
    assert device.log == ["T", "SI"]
