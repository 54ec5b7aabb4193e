"""NI-DAQmx adapter against fake task objects: channels, coerced sample clock, reference trigger, failures."""

from __future__ import annotations

import inspect
import subprocess
import sys

import numpy as np
import pytest

from drivers.errors import DeviceBusy, DeviceDisconnected, DeviceError, DeviceTimeout
from drivers.hw.acquisition import InputWiring
from drivers.hw.nidaq import NiDaq, ni_error
from drivers.interfaces import Channel, Daq, TriggerSpec
from tests.emulators import fake_nidaqmx as fake
from tests.emulators.fake_nidaqmx import FakeNiHardware

pytestmark = pytest.mark.waits  # on subprocesses and the emulated DAQ's real-time waits (tests/conftest.py)

G = 9.80665
N, PRE = 2048, 128
TRIGGER = TriggerSpec(level_n=20.0, pretrigger_samples=PRE)


def wiring() -> list[InputWiring]:
    return [
        InputWiring(Channel("F", "force", "N", 0.23e-3, 2200.0), "cDAQ1Mod1/ai0"),
        InputWiring(Channel("A1Z", "acceleration", "m/s^2", 0.1 / G, 490.0), "cDAQ1Mod1/ai1"),
        InputWiring(Channel("A4Z", "acceleration", "m/s^2", 0.1 / G, 490.0), "cDAQ1Mod2/ai3"),
    ]


def blow(fs: float, peak_n: float = 500.0, accel_peak: float = 150.0) -> dict[str, np.ndarray]:
    t = np.arange(N) / fs
    force = np.where((t > 0.01) & (t < 0.0103), peak_n * np.sin(np.pi * (t - 0.01) / 0.3e-3), 0.0)
    ring = accel_peak * np.exp(-30 * t) * np.sin(2 * np.pi * 745 * t) * (t > 0.01)
    return {"F": force, "A1Z": ring, "A4Z": -0.3 * ring}


def make(hardware: FakeNiHardware) -> NiDaq:
    return NiDaq(wiring(), nidaqmx_module=hardware.module())


def test_channels_and_sample_clock_as_actually_set() -> None:
    hardware = FakeNiHardware()
    daq = make(hardware)
    assert isinstance(daq, Daq)
    assert daq.configure(20480.0, N) == 25600.0  # an NI 9234 runs at 51.2 kS/s ÷ n
    assert daq.sample_rate_hz == 25600.0 and daq.requested_rate_hz == 20480.0
    assert daq.record_s == pytest.approx(N / 20480.0) and daq.n_samples == 2560  # the duration kept, not the count
    task = hardware.tasks[-1]
    force, accel, _ = task.ai_channels.added
    assert (force.kind, force.physical, force.name, force.max_val) == ("force", "cDAQ1Mod1/ai0", "F", 2200.0)
    assert force.settings["sensitivity"] == pytest.approx(0.23)
    assert force.settings["sensitivity_units"] is fake.ForceIEPESensorSensitivityUnits.MILLIVOLTS_PER_NEWTON
    assert accel.settings["sensitivity"] == pytest.approx(100.0)  # mV/g
    assert accel.settings["units"] is fake.AccelUnits.METERS_PER_SECOND_SQUARED
    assert accel.settings["current_excit_source"] is fake.ExcitationSource.INTERNAL
    assert accel.settings["current_excit_val"] == 0.002 and accel.min_val == -490.0
    assert all(c.ai_coupling is fake.Coupling.AC for c in task.ai_channels.added)  # IEPE current needs AC
    assert daq.coupling() == {"F": "AC", "A1Z": "AC", "A4Z": "AC"}
    assert task.timing.sample_mode is fake.AcquisitionType.FINITE and task.timing.samps_per_chan == 2560


def test_reference_trigger_record() -> None:
    hardware = FakeNiHardware()
    with make(hardware) as daq:
        fs = daq.configure(20480.0, N)
        daq.arm(TRIGGER)
        trig = hardware.tasks[-1].triggers.reference_trigger
        # the source is the force's virtual channel; the pretrigger keeps its 6.25 ms at the 25.6 kHz clock
        assert (trig.source, trig.pretrigger, trig.level, trig.slope) == ("F", 160, 20.0, fake.Slope.RISING)
        hardware.blow(blow(fs))
        record = daq.acquire(timeout_s=1.0)
    assert record.sample_rate_hz == 25600.0 and record.channels == ("A1Z", "A4Z") and record.trigger_index == 160
    assert record.force_n.size == 2560 and record.force_n[159] < 20.0 <= record.force_n[160]
    assert record.force_n.max() == pytest.approx(500.0, rel=0.01)
    onset = int(np.argmax(blow(fs)["F"] >= 20.0))
    expected = blow(fs)["A1Z"][onset - 160:]
    np.testing.assert_allclose(record.accel_m_per_s2[0, : expected.size], expected)
    assert record.clipped == ()
    assert hardware.tasks[-1].closed


def test_a_channel_left_dc_coupled_gets_no_iepe_current(monkeypatch: pytest.MonkeyPatch) -> None:
    """What the explicit AC coupling prevents: without it the (fake, as the real) module powers no sensor."""
    hardware = FakeNiHardware()
    monkeypatch.setattr(fake._Chan, "__setattr__", lambda self, k, v: None if k == "ai_coupling"
                        else object.__setattr__(self, k, v))
    with make(hardware) as daq:
        fs = daq.configure(20480.0, N)
        daq.arm(TRIGGER)
        hardware.blow(blow(fs))
        record = daq.acquire(timeout_s=1.0)
        assert daq.coupling()["A1Z"] == "DC"
    assert not np.any(record.accel_m_per_s2)


@pytest.mark.parametrize(("rule", "rate", "samples", "pre"), [("up", 25600.0, 81920, 320),
                                                             ("nearest", 51200.0 / 3, 54613, 213)])
def test_the_protocols_record_length_is_kept_in_seconds(rule: str, rate: float, samples: int, pre: int) -> None:
    """20 480 Hz × 65 536 samples = 3.2 s with 256 pretrigger samples (12.5 ms), at whichever rate the module sets."""
    hardware = FakeNiHardware(rate_rule=rule)
    daq = make(hardware)
    assert daq.configure(20480.0, 65536) == pytest.approx(rate)
    assert daq.n_samples == samples and samples / rate == pytest.approx(3.2, abs=0.5 / rate)
    assert daq.pretrigger_at_rate(256) == pre and pre / rate == pytest.approx(12.5e-3, abs=0.5 / rate)
    assert hardware.tasks[-1].timing.samps_per_chan == samples


def test_rearming_reuses_the_task() -> None:
    hardware = FakeNiHardware()
    with make(hardware) as daq:
        fs = daq.configure(20480.0, N)
        for _ in range(2):
            daq.arm(TRIGGER)
            hardware.blow(blow(fs))
            daq.acquire(1.0)
        assert len(hardware.tasks) == 1 and hardware.tasks[0].starts == 2


def test_overloaded_channel_is_flagged() -> None:
    hardware = FakeNiHardware()
    with make(hardware) as daq:
        fs = daq.configure(20480.0, N)
        daq.arm(TRIGGER)
        hardware.blow(blow(fs, accel_peak=900.0))
        assert daq.acquire(1.0).clipped == ("A1Z",)


def test_no_trigger_times_out() -> None:
    with make(FakeNiHardware()) as daq:
        daq.configure(20480.0, N)
        daq.arm(TRIGGER)
        with pytest.raises(DeviceTimeout, match="-200560"):
            daq.acquire(timeout_s=0.05)


def test_failures_are_typed() -> None:
    with pytest.raises(DeviceDisconnected, match="-200220"):
        make(FakeNiHardware(devices=("cDAQ1Mod1",))).configure(20480.0, N)
    busy = FakeNiHardware(reserved=True)
    daq = make(busy)
    daq.configure(20480.0, N)
    with pytest.raises(DeviceBusy, match="another task"):
        daq.arm(TRIGGER)
    gone = FakeNiHardware()
    daq = make(gone)
    daq.configure(20480.0, N)
    daq.arm(TRIGGER)
    gone.removed = True
    with pytest.raises(DeviceDisconnected, match="device cannot be accessed.*-201003"):
        daq.acquire(1.0)
    with pytest.raises(DeviceError, match="configure"):
        make(FakeNiHardware()).arm(TRIGGER)
    unarmed = make(FakeNiHardware())
    unarmed.configure(20480.0, N)
    with pytest.raises(DeviceError, match="not armed"):
        unarmed.acquire(0.1)


def test_probe_names_missing_modules_and_wrong_products() -> None:
    assert "cDAQ1Mod1, cDAQ1Mod2" in make(FakeNiHardware()).probe()
    with pytest.raises(DeviceDisconnected, match="not present: cDAQ1Mod2"):
        make(FakeNiHardware(devices=("cDAQ1Mod1",))).probe()
    assert "NI 9234 devices" in NiDaq(wiring(), nidaqmx_module=FakeNiHardware().module(), module_type="NI 9234").probe()
    other = FakeNiHardware(product_type="NI 9239").module()
    with pytest.raises(DeviceError, match="cDAQ1Mod1 is an NI 9239.*not the NI 9234"):
        NiDaq(wiring(), nidaqmx_module=other, module_type="NI 9234").probe()


@pytest.mark.parametrize(("code", "kind", "fragment"), [
    (-201401, DeviceDisconnected, "could not read a network device's properties"),
    (-200045, DeviceDisconnected, "device removed"),
    (-200220, DeviceDisconnected, "not present"),
    (-50103, DeviceBusy, "another task"),
])
def test_daqmx_codes_are_described_as_nidaqmx_names_them(code: int, kind: type, fragment: str) -> None:
    err = ni_error("daq", "arm", fake.DaqError("text", code))
    assert isinstance(err, kind) and fragment in str(err)


def test_without_nidaqmx_the_adapter_says_how_to_install_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "nidaqmx", None)  # import nidaqmx -> ImportError
    with pytest.raises(DeviceError, match=r"pip install 'labctl\[hw\]'"):
        NiDaq(wiring()).configure(20480.0, N)


def test_nidaqmx_is_imported_only_when_used() -> None:
    code = "import sys, drivers.hw, labctl.hardware; print('nidaqmx' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_fake_tasks_match_the_real_api() -> None:
    """The fake keeps the real method and parameter names, so the adapter's calls would work on hardware."""
    nidaqmx = pytest.importorskip("nidaqmx")
    from nidaqmx.task._timing import Timing
    from nidaqmx.task.collections._ai_channel_collection import AIChannelCollection
    from nidaqmx.task.triggering._reference_trigger import ReferenceTrigger

    pairs = [(fake._AIChannels.add_ai_accel_chan, AIChannelCollection.add_ai_accel_chan),
             (fake._AIChannels.add_ai_force_iepe_chan, AIChannelCollection.add_ai_force_iepe_chan),
             (fake._Timing.cfg_samp_clk_timing, Timing.cfg_samp_clk_timing),
             (fake._ReferenceTrigger.cfg_anlg_edge_ref_trig, ReferenceTrigger.cfg_anlg_edge_ref_trig),
             (fake.FakeTask.read, nidaqmx.Task.read), (fake.FakeTask.wait_until_done, nidaqmx.Task.wait_until_done)]
    for ours, real in pairs:
        assert list(inspect.signature(ours).parameters) == list(inspect.signature(real).parameters), real.__name__
    for enum_class in (fake.AccelUnits, fake.ForceUnits, fake.Slope, fake.AcquisitionType, fake.ExcitationSource,
                       fake.Coupling,
                       fake.AccelSensitivityUnits, fake.ForceIEPESensorSensitivityUnits):
        real_enum = getattr(nidaqmx.constants, enum_class.__name__)
        for member in enum_class:
            assert real_enum[member.name].value == member.value
    assert nidaqmx.errors.DaqError.__init__.__code__.co_varnames[1:4] == ("message", "error_code", "task_name")
