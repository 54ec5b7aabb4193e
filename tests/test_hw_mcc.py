"""USB-1608FS-Plus driver through real pyusb code against a fake device behind a custom backend."""

from __future__ import annotations

import errno
import struct

import numpy as np
import pytest

from drivers.errors import DeviceBusy, DeviceDisconnected, DeviceError, DeviceTimeout
from drivers.hw import mcc_protocol as mcc
from drivers.hw.acquisition import InputWiring
from drivers.hw.mcc_usb import MccUsbDaq
from drivers.interfaces import Channel, Daq
from tests.emulators.fake_usb import MAKER_RANGES_V, FakeMcc1608, FakeUsbBackend, PlaybackSource, default_calibration
from tests.emulators.impacts import ACCEL_V_PER_MS2, FORCE_V_PER_N, FS, PRE, TRIGGER, N, impact_volts, wiring


def rig(*devices: FakeMcc1608, serial: str | None = None) -> MccUsbDaq:
    daq = MccUsbDaq(wiring(), serial=serial, backend=FakeUsbBackend(*devices))
    assert daq.configure(FS, N) == pytest.approx(40e6 / 1953)
    return daq


def test_pacer_gives_the_rate_the_device_really_runs_at() -> None:
    assert mcc.pacer_period(20480.0) == 1952
    assert mcc.actual_rate_hz(mcc.pacer_period(20480.0)) == pytest.approx(20481.3, abs=0.05)
    for rate in (1000.0, 12800.0, 51200.0, 100e3):
        period = mcc.pacer_period(rate)
        assert mcc.actual_rate_hz(period) == pytest.approx(40e6 / round(40e6 / rate))
    with pytest.raises(ValueError, match="100000 Hz"):
        mcc.pacer_period(200e3)


def test_calibration_table_and_code_conversion() -> None:
    slope, intercept = np.full((8, 8), 1.0), np.zeros((8, 8))
    intercept[5, 3] = 10.0
    cal = mcc.Calibration.from_memory(np.stack([slope, intercept], -1).astype("<f4").tobytes())
    codes = np.array([[32768, 65535, 0]], dtype=np.uint16)
    assert cal.volts(codes, (0,), (0,)).tolist() == [[0.0, 10.0 * 32767 / 32768, -10.0]]
    assert cal.volts(np.array([[32758]]), (3,), (5,))[0, 0] == 0.0  # intercept applied per range and channel
    with pytest.raises(ValueError, match="blank"):
        mcc.Calibration.from_memory(b"\xff" * mcc.CAL_TABLE_BYTES)


def test_the_record_keeps_its_duration_at_the_pacers_rate() -> None:
    """20 480 Hz × 65 536 samples asked = 3.2 s: 65 540 samples at the 20 481.3 Hz the pacer runs at."""
    daq = MccUsbDaq(wiring())
    assert daq.configure(20480.0, 65536) == pytest.approx(40e6 / 1953)
    assert daq.n_samples == 65540 and daq.n_samples / daq.sample_rate_hz == pytest.approx(3.2, abs=1e-4)


def test_input_ranges_are_the_makers_four() -> None:
    """User's Guide p. 11 and uldaq mapRangeCode: ±10/±5/±2/±1 V as codes 0/1/3/5 — not the USB-1608FS's eight."""
    assert mcc.RANGES_V == MAKER_RANGES_V
    # the hammer (0.23 mV/N × 2200 N = 0.506 V) goes on ±1 V; the old table's ±0.625 V (code 6) does not exist
    assert mcc.range_code(None, 0.506) == 5
    assert mcc.range_code(None, 1.5) == 3 and mcc.range_code(None, 5.0) == 1 and mcc.range_code(None, 30) == 0
    for missing in (2.5, 1.25, 0.625, 0.3125):
        with pytest.raises(ValueError, match=r"±10, ±5, ±2, ±1 V"):
            mcc.range_code(missing, 0.1)


def test_unused_calibration_slots_may_be_blank_but_used_ones_may_not() -> None:
    """The maker's driver reads coefficients only at the range slots 0, 1, 3, 5 (uldaq getCalCoefIndex)."""
    slope, intercept = default_calibration()  # slots 2, 4, 6, 7 erased, as on a healthy unit
    raw = np.stack([slope, intercept], -1).astype("<f4").tobytes()
    cal = mcc.Calibration.from_memory(raw)
    assert cal.slope[1, 4] == pytest.approx(slope[1, 4])
    slope[3, 6] = np.nan
    with pytest.raises(ValueError, match=r"±2 V range \(slot 3\) is blank or corrupt"):
        mcc.Calibration.from_memory(np.stack([slope, intercept], -1).astype("<f4").tobytes())


def test_aggregate_rate_is_checked() -> None:
    """100 kS/s per channel but 400 kS/s in all when streaming (DAQFlex hardware reference, USB-1608FS-Plus)."""
    assert mcc.pacer_period(50e3, 8) == 799 and mcc.pacer_period(100e3, 4) == 399
    with pytest.raises(ValueError, match=r"400000 S/s in all \(at most 50000 Hz for 8 channels\)"):
        mcc.pacer_period(60e3, 8)
    daq = MccUsbDaq([*wiring(), *(InputWiring(Channel(f"A{i}X", "acceleration", "m/s^2", ACCEL_V_PER_MS2, 490.0),
                                               str(i + 2)) for i in (1, 2, 3))])
    with pytest.raises(ValueError, match="6 channels"):
        daq.configure(80e3, 4096)
    assert daq.configure(40e3, 4096) == pytest.approx(40e3)


def test_triggered_record_in_physical_units() -> None:
    source = PlaybackSource(noise_v=1e-5)
    device = FakeMcc1608(source)
    volts = impact_volts(FS)
    with rig(device) as daq:
        assert isinstance(daq, Daq)
        daq.arm(TRIGGER)
        source.play(volts, delay_scans=2000)
        record = daq.acquire(timeout_s=5.0)
    assert record.channels == ("A1Z", "A2Z") and record.trigger_index == PRE and record.clipped == ()
    assert record.force_n.shape == (N,) and record.accel_m_per_s2.shape == (2, N)
    assert record.force_n[PRE - 1] < TRIGGER.level_n <= record.force_n[PRE]
    onset = PRE - int(np.argmax(volts[0] / FORCE_V_PER_N >= TRIGGER.level_n))
    expected_force = volts[0, : N - onset] / FORCE_V_PER_N
    np.testing.assert_allclose(record.force_n[onset:], expected_force, atol=0.3)  # ±1 V range, 16 bit
    np.testing.assert_allclose(record.accel_m_per_s2[0, onset:], volts[2, : N - onset] / ACCEL_V_PER_MS2, atol=0.1)
    np.testing.assert_allclose(record.accel_m_per_s2[1, onset:], volts[1, : N - onset] / ACCEL_V_PER_MS2, atol=0.1)
    assert record.sample_rate_hz == pytest.approx(20481.3, abs=0.05)
    # the unit was told: ranges per input, then a continuous scan of inputs 0-2 at the pacer period
    assert device.ranges[:3] == [5, 1, 1]  # F on ±1 V (0.506 V full scale), the accelerometers on ±5 V
    assert (device.count, device.period, device.mask) == (0, 1952, 0b111)
    assert not device.running
    assert [c.range_units for c in daq.channels] == pytest.approx([2200.0, 490.0, 490.0])
    assert daq.input_ranges_v == {"F": 1.0, "A1Z": 5.0, "A2Z": 5.0}


def test_scan_left_running_by_a_crashed_program_is_stopped_first() -> None:
    source = PlaybackSource()
    device = FakeMcc1608(source)
    device.leave_scan_running()
    with rig(device) as daq:
        assert daq.stale_scan_stopped
        assert device.log[:2] == ["STOP", "CLEAR_FIFO"]
        assert "CAL" in device.log and "CAL (scan running)" not in device.log  # calibration read after the stop
        daq.arm(TRIGGER)
        source.play(impact_volts(FS), delay_scans=1000)
        assert daq.acquire(5.0).force_n.max() > 500


def test_no_blow_times_out_and_stops_the_scan() -> None:
    device = FakeMcc1608()
    with rig(device) as daq:
        with pytest.raises(DeviceError, match="not armed"):
            daq.acquire(timeout_s=0.1)
        daq.arm(TRIGGER)
        with pytest.raises(DeviceTimeout, match="no force above the trigger level within 0.2 s"):
            daq.acquire(timeout_s=0.2)
        assert not device.running


def test_fifo_overrun_is_reported_and_the_stall_cleared() -> None:
    source = PlaybackSource()
    device = FakeMcc1608(source)
    device.overrun_after_scans = 3000
    with rig(device) as daq:
        daq.arm(TRIGGER)
        with pytest.raises(DeviceError, match="FIFO overrun"):
            daq.acquire(5.0)
        assert not device.stalled
        device.overrun_after_scans = None
        daq.arm(TRIGGER)
        source.play(impact_volts(FS), delay_scans=500)
        assert daq.acquire(5.0).trigger_index == PRE


def test_unplug_mid_stream_is_disconnected() -> None:
    device = FakeMcc1608()
    device.unplug_after_scans = 2000
    with rig(device) as daq:
        daq.arm(TRIGGER)
        with pytest.raises(DeviceDisconnected, match="ENODEV"):
            daq.acquire(5.0)


def test_zero_length_packets_do_not_disturb_the_stream() -> None:
    source = PlaybackSource(noise_v=0.0)
    device = FakeMcc1608(source)
    device.zlp_every = 3
    volts = impact_volts(FS)
    with rig(device) as daq:
        daq.arm(TRIGGER)
        source.play(volts, delay_scans=700)
        record = daq.acquire(5.0)
    onset = PRE - int(np.argmax(volts[0] / FORCE_V_PER_N >= TRIGGER.level_n))
    np.testing.assert_allclose(record.force_n[onset:onset + 100], volts[0, :100] / FORCE_V_PER_N, atol=0.3)


def test_clipped_input_is_flagged() -> None:
    source = PlaybackSource()
    with rig(FakeMcc1608(source)) as daq:
        daq.arm(TRIGGER)
        source.play(impact_volts(FS, peak_n=5000.0), delay_scans=500)  # 1.15 V on the ±1 V range
        assert daq.acquire(5.0).clipped == ("F",)


@pytest.mark.parametrize(("attr", "code", "kind", "fragment"), [
    ("open_errno", errno.EACCES, DeviceError, "udev"),
    ("claim_errno", errno.EBUSY, DeviceBusy, "another program"),
])
def test_open_refusals(attr: str, code: int, kind: type, fragment: str) -> None:
    device = FakeMcc1608()
    setattr(device, attr, code)
    with pytest.raises(kind, match=fragment):
        rig(device).open()


def test_missing_unit() -> None:
    with pytest.raises(DeviceDisconnected, match="vendor 0x09db, product 0x00ea"):
        rig().open()


def test_several_units_need_a_serial_number() -> None:
    first, second = FakeMcc1608(serial="AAAA0001", address=5), FakeMcc1608(serial="BBBB0002", address=6)
    with pytest.raises(DeviceError, match=r"AAAA0001.*BBBB0002.*daq.serial"):
        rig(first, second).open()
    with rig(first, second, serial="BBBB0002") as daq:
        assert "BBBB0002" in daq.probe()
    with pytest.raises(DeviceError, match="no unit with serial CCCC"):
        rig(first, second, serial="CCCC0003").open()


def test_wiring_is_checked() -> None:
    bad_input = [*wiring()[:2], InputWiring(Channel("A3Z", "acceleration", "m/s^2", 0.01, 490.0), "8")]
    with pytest.raises(ValueError, match="inputs 0-7"):
        MccUsbDaq(bad_input)
    two_forces = [*wiring(), InputWiring(Channel("F2", "force", "N", 0.001, 100.0), "5")]
    with pytest.raises(ValueError, match="exactly one force channel"):
        MccUsbDaq(two_forces)


def test_scan_start_packet_layout() -> None:
    assert mcc.scan_start_packet(0b101, 1952) == struct.pack("<IIBB", 0, 1952, 5, 0)
