"""Self-test of the emulators written from the makers' documents, through their public surfaces only:
pyusb calls (USB-1608FS-Plus), the nidaqmx API (NI 9234) and serial bytes (MT-SICS). No labctl driver is used."""

from __future__ import annotations

import errno
import math
import struct
import time

import pytest
import serial
import usb.core

from tests.emulators import maker_mcc1608fsplus as mcc
from tests.emulators import maker_mtsics as mt
from tests.emulators import maker_ni9234 as ni
from tests.emulators.maker_mcc1608fsplus_backend import Usb1608FsPlusBackend

pytestmark = pytest.mark.waits  # on emulated instruments answering in real time (tests/conftest.py)

VENDOR_OUT, VENDOR_IN = 0x40, 0xC0


# -- MCC USB-1608FS-Plus -------------------------------------------------------------------------------------------
def _open(volts, **kw) -> tuple[usb.core.Device, mcc.Usb1608FsPlus]:
    unit = mcc.Usb1608FsPlus(volts, **kw)
    dev = usb.core.find(idVendor=0x09DB, idProduct=0x00EA, backend=Usb1608FsPlusBackend(unit))
    assert dev is not None
    dev.set_configuration()
    return dev, unit


def _cal(dev: usb.core.Device, code: int, channel: int) -> tuple[float, float]:
    mem = bytes(dev.ctrl_transfer(VENDOR_IN, mcc.CAL_MEMORY, 0, 0, 0x200))
    addr = 8 * (8 * code + channel)
    return struct.unpack("<ff", mem[addr : addr + 8])


def test_mcc_enumerates_with_the_makers_ids_and_one_64_byte_bulk_in_endpoint():
    dev, _ = _open(lambda ch, t: 0.0)
    assert (dev.idVendor, dev.idProduct) == (0x09DB, 0x00EA)
    assert dev.serial_number == "01F2A3B4"
    ep = dev[0][(0, 0)][0]
    assert (ep.bEndpointAddress, ep.wMaxPacketSize) == (0x81, 64)


@pytest.mark.parametrize(("code", "full_scale_v"), [(0, 10.0), (1, 5.0), (3, 2.0), (5, 1.0)])
def test_mcc_range_codes_decode_to_the_units_full_scales_through_the_cal_table(code, full_scale_v):
    applied_v = 0.37 * full_scale_v
    dev, _ = _open(lambda ch, t: applied_v)
    raw = struct.unpack("<H", bytes(dev.ctrl_transfer(VENDOR_IN, mcc.AIN, 2, code, 2)))[0]
    slope, offset = _cal(dev, code, 2)
    corrected = raw * slope + offset
    volts = (corrected - 32768) * full_scale_v / 32768
    assert volts == pytest.approx(applied_v, abs=1.5 * full_scale_v / 32768)
    # without the correction the reading is off by many counts: the table matters
    assert abs((raw - 32768) * full_scale_v / 32768 - applied_v) > 10 * full_scale_v / 32768


@pytest.mark.parametrize("code", [2, 4, 6, 7, 8])
def test_mcc_stalls_on_a_range_code_it_does_not_have(code):
    dev, _ = _open(lambda ch, t: 0.0)
    with pytest.raises(usb.core.USBError) as err:
        dev.ctrl_transfer(VENDOR_IN, mcc.AIN, 0, code, 2)
    assert err.value.errno == errno.EPIPE
    with pytest.raises(usb.core.USBError):
        dev.ctrl_transfer(VENDOR_OUT, mcc.AIN_CONFIG, 0, 0, bytes([0] * 7 + [code]))
    assert list(dev.ctrl_transfer(VENDOR_IN, mcc.AIN_CONFIG, 0, 0, 8)) == [0] * 8  # config unchanged


def test_mcc_unused_cal_slots_are_erased_and_used_ones_are_finite():
    dev, _ = _open(lambda ch, t: 0.0)
    assert all(math.isfinite(v) for v in _cal(dev, 3, 7))
    assert all(math.isnan(v) for v in _cal(dev, 2, 0))


def _start(dev, count, rate_hz, mask, options=0):
    period = round(40e6 / rate_hz) - 1
    dev.ctrl_transfer(VENDOR_OUT, mcc.AIN_SCAN_START, 0, 0, struct.pack("<IIBB", count, period, mask, options))


def test_mcc_scan_interleaves_channels_at_the_pacer_rate_and_ends_with_a_zero_length_packet():
    f_hz = 250.0
    dev, _ = _open(lambda ch, t: (ch + 1) * 0.5 * math.sin(2 * math.pi * f_hz * t))
    dev.ctrl_transfer(VENDOR_OUT, mcc.AIN_CONFIG, 0, 0, bytes([1, 0, 0, 0, 0, 0, 0, 0]))
    n_scans = 1024  # 2 channels x 2 bytes x 1024 = 4096 bytes, a whole number of 64-byte packets
    _start(dev, n_scans, 10_000.0, 0b11)
    assert dev.ctrl_transfer(VENDOR_IN, mcc.STATUS, 0, 0, 2)[0] & mcc.STATUS_SCAN_RUNNING
    data = bytes(dev.read(0x81, 4 * n_scans, 1000))
    assert len(data) == 4 * n_scans
    assert len(dev.read(0x81, 64, 100)) == 0  # the zero-length packet
    assert not dev.ctrl_transfer(VENDOR_IN, mcc.STATUS, 0, 0, 2)[0] & mcc.STATUS_SCAN_RUNNING
    codes = struct.unpack(f"<{2 * n_scans}H", data)
    (s0, o0), (s1, o1) = _cal(dev, 1, 0), _cal(dev, 0, 1)
    ch0 = [(c * s0 + o0 - 32768) * 5.0 / 32768 for c in codes[0::2]]  # ch0 on the +-5 V range (code 1)
    ch1 = [(c * s1 + o1 - 32768) * 10.0 / 32768 for c in codes[1::2]]
    assert max(ch0) == pytest.approx(0.5, abs=3e-4) and max(ch1) == pytest.approx(1.0, abs=6e-4)
    crossings = sum(1 for a, b in zip(ch0, ch0[1:], strict=False) if a < 0 <= b)
    assert crossings == pytest.approx(f_hz * n_scans / 10_000.0, abs=1)


def test_mcc_refuses_a_pacer_above_100_khz_and_a_second_start():
    dev, _ = _open(lambda ch, t: 0.0)
    with pytest.raises(usb.core.USBError):
        _start(dev, 10, 200_000.0, 0b1)
    _start(dev, 10, 1000.0, 0b1)
    with pytest.raises(usb.core.USBError):
        _start(dev, 10, 1000.0, 0b1)
    with pytest.raises(usb.core.USBError):  # no single reads while a scan runs
        dev.ctrl_transfer(VENDOR_IN, mcc.AIN, 0, 0, 2)


def test_mcc_overruns_past_the_fifo_when_streaming_above_400_kS_s_and_stalls_the_pipe():
    dev, unit = _open(lambda ch, t: 0.0)
    _start(dev, 0, 100_000.0, 0xFF)  # 8 x 100 kS/s = 800 kS/s: the FIFO fills at 400 kS/s
    got = 0
    with pytest.raises(usb.core.USBError) as err:
        while True:
            got += len(dev.read(0x81, 8192, 1000))
    assert err.value.errno == errno.EPIPE
    assert got // 2 == 65536  # 32768 samples of FIFO / (1 - 400/800)
    assert dev.ctrl_transfer(VENDOR_IN, mcc.STATUS, 0, 0, 2)[0] & mcc.STATUS_SCAN_OVERRUN
    dev.clear_halt(0x81)
    assert not unit.halted


def test_mcc_sends_nothing_until_its_trigger_arrives():
    dev, _ = _open(lambda ch, t: 0.0, trigger_time_s=None)
    _start(dev, 10, 1000.0, 0b1, options=1 << 2)  # edge / rising
    with pytest.raises(usb.core.USBTimeoutError):
        dev.read(0x81, 64, 100)


# -- NI 9234 through the nidaqmx API ------------------------------------------------------------------------------
def _chassis() -> ni.Chassis:
    return ni.Chassis(modules={1: {0: ni.Input(lambda t: 0.1 * math.sin(2 * math.pi * 160 * t)),
                                   1: ni.Input(lambda t: 0.5 if t >= 0.02 else 0.0, iepe_sensor=False)}},
                      digital_edges_s={"/cDAQ1/PFI0": [0.01]})


def test_ni_constants_carry_the_real_packages_values():
    assert ni.AcquisitionType.FINITE.value == 10178 and ni.AcquisitionType.CONTINUOUS.value == 10123
    assert (ni.Coupling.AC.value, ni.Coupling.DC.value) == (10045, 10050)
    assert ni.ExcitationSource.INTERNAL.value == 10200 and ni.AccelUnits.G.value == 10186
    assert ni.AccelSensitivityUnits.MILLIVOLTS_PER_G.value == 12509 and ni.Edge.RISING.value == 10280


@pytest.mark.parametrize(("requested", "coerced"), [(51200.0, 51200.0), (10_000.0, 10240.0), (25_000.0, 25600.0),
                                                    (1700.0, 51200.0 / 30)])
def test_ni_rate_is_coerced_up_to_the_next_51_2k_over_n_rate(requested, coerced):
    with ni.installed(_chassis()):
        import nidaqmx

        with nidaqmx.Task() as task:
            task.ai_channels.add_ai_voltage_chan("cDAQ1Mod1/ai1")
            task.timing.cfg_samp_clk_timing(requested)
            assert task.timing.samp_clk_rate == pytest.approx(coerced)


@pytest.mark.parametrize("requested", [60_000.0, 1000.0])
def test_ni_rate_outside_the_modules_range_is_error_200077(requested):
    with ni.installed(_chassis()):
        import nidaqmx

        with nidaqmx.Task() as task:
            task.ai_channels.add_ai_voltage_chan("cDAQ1Mod1/ai1")
            task.timing.cfg_samp_clk_timing(requested)
            with pytest.raises(nidaqmx.errors.DaqError) as err:
                task.start()
            assert err.value.error_code == -200077


def test_ni_iepe_needs_ac_coupling_and_2_mA():
    with ni.installed(_chassis()):
        import nidaqmx
        from nidaqmx.constants import Coupling

        with nidaqmx.Task() as task:  # the package default of 4 mA is not a 9234 value
            task.ai_channels.add_ai_accel_chan("cDAQ1Mod1/ai0", sensitivity=100.0, min_val=-40.0, max_val=40.0)
            with pytest.raises(nidaqmx.errors.DaqError, match="AI.Excit.Val") as err:
                task.start()
            assert err.value.error_code == -200077
        with nidaqmx.Task() as task:
            chan = task.ai_channels.add_ai_accel_chan("cDAQ1Mod1/ai0", sensitivity=100.0, min_val=-40.0,
                                                      max_val=40.0, current_excit_val=0.002)
            chan.ai_coupling = Coupling.DC
            with pytest.raises(nidaqmx.errors.DaqError, match="AI.Coupling"):
                task.start()


def test_ni_accel_channel_scales_volts_by_sensitivity_and_an_unpowered_iepe_sensor_is_silent():
    with ni.installed(_chassis()):
        import nidaqmx
        from nidaqmx.constants import AccelUnits, AcquisitionType, ExcitationSource

        with nidaqmx.Task() as task:
            task.ai_channels.add_ai_accel_chan("cDAQ1Mod1/ai0", sensitivity=100.0, min_val=-40.0, max_val=40.0,
                                               units=AccelUnits.METERS_PER_SECOND_SQUARED, current_excit_val=0.002)
            task.timing.cfg_samp_clk_timing(51200.0, sample_mode=AcquisitionType.FINITE, samps_per_chan=5120)
            task.start()
            data = task.read(5120)
        assert max(data[2560:]) == pytest.approx(9.80665, rel=0.01)  # 0.1 V at 100 mV/g = 1 g
        with nidaqmx.Task() as task:
            task.ai_channels.add_ai_accel_chan("cDAQ1Mod1/ai0", sensitivity=100.0, min_val=-40.0, max_val=40.0,
                                               current_excit_source=ExcitationSource.NONE)
            task.timing.cfg_samp_clk_timing(51200.0, samps_per_chan=100)
            assert max(abs(v) for v in task.read(100)) == 0.0


def test_ni_reference_trigger_puts_the_trigger_sample_after_the_pretrigger_samples():
    with ni.installed(_chassis()):
        import nidaqmx

        with nidaqmx.Task() as task:
            task.ai_channels.add_ai_voltage_chan("cDAQ1Mod1/ai1")
            task.timing.cfg_samp_clk_timing(25600.0, samps_per_chan=1000)
            task.triggers.reference_trigger.cfg_anlg_edge_ref_trig("cDAQ1Mod1/ai1", 200, trigger_level=0.25)
            task.start()
            data = task.read(1000)
        assert data[199] == 0.0 and data[200] == 0.5


def test_ni_start_trigger_digital_edge_and_a_trigger_that_never_comes():
    with ni.installed(_chassis()):
        import nidaqmx

        with nidaqmx.Task() as task:
            task.ai_channels.add_ai_voltage_chan("cDAQ1Mod1/ai1")
            task.timing.cfg_samp_clk_timing(25600.0, samps_per_chan=512)
            task.triggers.start_trigger.cfg_dig_edge_start_trig("/cDAQ1/PFI0")
            task.start()
            data = task.read(512)
        first_high = data.index(0.5)  # input steps at 20 ms, acquisition starts at the 10 ms edge
        assert first_high == pytest.approx(0.01 * 25600, abs=1)
        with nidaqmx.Task() as task:
            task.ai_channels.add_ai_voltage_chan("cDAQ1Mod1/ai1")
            task.timing.cfg_samp_clk_timing(25600.0, samps_per_chan=512)
            task.triggers.start_trigger.cfg_anlg_edge_start_trig("cDAQ1Mod1/ai1", trigger_level=0.75)
            task.start()
            with pytest.raises(nidaqmx.errors.DaqError) as err:
                task.read(512, timeout=0.2)
            assert err.value.error_code == -200284


def test_ni_stream_reader_fills_a_channels_by_samples_array():
    import numpy as np

    with ni.installed(_chassis()):
        import nidaqmx
        from nidaqmx.stream_readers import AnalogMultiChannelReader

        with nidaqmx.Task() as task:
            task.ai_channels.add_ai_voltage_chan("cDAQ1Mod1/ai1")
            task.ai_channels.add_ai_accel_chan("cDAQ1Mod1/ai0", sensitivity=100.0, min_val=-40.0, max_val=40.0,
                                               current_excit_val=0.002)
            task.timing.cfg_samp_clk_timing(12800.0, samps_per_chan=1280)
            task.start()
            data = np.zeros((2, 1280))
            assert AnalogMultiChannelReader(task.in_stream).read_many_sample(data, 1280) == 1280
        assert data[0, 0] == 0.0 and data[0, -1] == 0.5  # ai1 steps at 20 ms
        assert np.max(data[1, 640:]) == pytest.approx(1.0, rel=0.01)  # ai0: 1 g


def test_ni_unknown_physical_channel_is_error_200170():
    with ni.installed(_chassis()):
        import nidaqmx

        with nidaqmx.Task() as task, pytest.raises(nidaqmx.errors.DaqError) as err:
            task.ai_channels.add_ai_voltage_chan("cDAQ1Mod3/ai0")
        assert err.value.error_code == -200170


# -- MT-SICS balance over serial bytes ----------------------------------------------------------------------------
def _ask(port: serial.Serial, command: bytes) -> bytes:
    port.write(command + b"\r\n")
    return port.readline()


def test_mtsics_level_0_balance_knows_no_level_1_command():
    with mt.MtSicsBalance(level=0) as balance, serial.Serial(balance.port, 9600, timeout=2, xonxoff=True) as port:
        balance.load_g = 12.5
        assert _ask(port, b"S") == b"S S      12.50 g\r\n"
        assert _ask(port, b"T") == b"ES\r\n"
        assert _ask(port, b"I1") == b'I1 A "0" "2.20" "2.20" "" ""\r\n'
        assert _ask(port, b"s") == b"ES\r\n"  # commands are upper case


def test_mtsics_level_1_tare_zero_and_weight_states():
    with mt.MtSicsBalance(level=1, stable_timeout_s=0.2) as balance, \
            serial.Serial(balance.port, 9600, timeout=2, xonxoff=True) as port:
        balance.load_g = 1.0
        assert _ask(port, b"Z") == b"Z A\r\n"
        balance.load_g = 51.0
        assert _ask(port, b"T") == b"T S      50.00 g\r\n"
        balance.load_g = 61.0
        assert _ask(port, b"S") == b"S S      10.00 g\r\n"
        assert _ask(port, b"TAC") == b"TAC A\r\n"
        assert _ask(port, b"SI") == b"S S      60.00 g\r\n"
        balance.stable = False
        assert _ask(port, b"SI") == b"S D      60.00 g\r\n"
        assert _ask(port, b"S") == b"S I\r\n"  # no stability within the timeout
        balance.load_g = 500.0
        assert _ask(port, b"SI") == b"S +\r\n"


def test_mtsics_8n1_host_against_a_7e1_balance_gets_et_with_parity_in_bit_7():
    with mt.MtSicsBalance(fmt=mt.SerialFormat(7, "E", 1, True)) as balance:
        observed = balance.observing_serial()
        with observed(balance.port, 9600, timeout=2) as port:
            reply = _ask(port, b"S")
        # the CR of the command fails the balance's even-parity check; its "ET" arrives with parity bits set
        assert reply == bytes([0x45 | 0x80, 0x54 | 0x80, 0x0D | 0x80, 0x0A])
        with observed(balance.port, 9600, timeout=2, bytesize=7, parity="E") as port:
            assert _ask(port, b"I4") == b'I4 A "B021002593"\r\n'


def test_mtsics_xoff_holds_the_reply_until_xon():
    with mt.MtSicsBalance(fmt=mt.SerialFormat(xonxoff=True)) as balance, \
            serial.Serial(balance.port, 9600, timeout=0.3) as port:
        port.write(bytes([mt.XOFF]) + b"SI\r\n")
        assert port.readline() == b""
        port.timeout = 2
        port.write(bytes([mt.XON]))
        deadline = time.monotonic() + 2
        reply = port.readline()
        assert reply == b"S S       0.00 g\r\n" and time.monotonic() < deadline
