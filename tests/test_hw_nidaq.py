"""NI-DAQmx adapter against fake task objects: channels, coerced sample clock, reference trigger, failures."""

from __future__ import annotations

import inspect
import subprocess
import sys

import numpy as np
import pytest

from drivers.errors import DeviceBusy, DeviceDisconnected, DeviceError, DeviceTimeout
from drivers.hw.acquisition import InputWiring
from drivers.hw.nidaq import NiDaq
from drivers.interfaces import Channel, Daq, TriggerSpec
from tests.emulators import fake_nidaqmx as fake
from tests.emulators.fake_nidaqmx import FakeNiHardware

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
    task = hardware.tasks[-1]
    force, accel, _ = task.ai_channels.added
    assert (force.kind, force.physical, force.name, force.max_val) == ("force", "cDAQ1Mod1/ai0", "F", 2200.0)
    assert force.settings["sensitivity"] == pytest.approx(0.23)
    assert force.settings["sensitivity_units"] is fake.ForceIEPESensorSensitivityUnits.MILLIVOLTS_PER_NEWTON
    assert accel.settings["sensitivity"] == pytest.approx(100.0)  # mV/g
    assert accel.settings["units"] is fake.AccelUnits.METERS_PER_SECOND_SQUARED
    assert accel.settings["current_excit_source"] is fake.ExcitationSource.INTERNAL
    assert accel.settings["current_excit_val"] == 0.002 and accel.min_val == -490.0
    assert task.timing.sample_mode is fake.AcquisitionType.FINITE and task.timing.samps_per_chan == N


def test_reference_trigger_record() -> None:
    hardware = FakeNiHardware()
    with make(hardware) as daq:
        fs = daq.configure(20480.0, N)
        daq.arm(TRIGGER)
        trig = hardware.tasks[-1].triggers.reference_trigger
        assert (trig.source, trig.pretrigger, trig.level, trig.slope) == ("cDAQ1Mod1/ai0", PRE, 20.0, fake.Slope.RISING)
        hardware.blow(blow(fs))
        record = daq.acquire(timeout_s=1.0)
    assert record.sample_rate_hz == 25600.0 and record.channels == ("A1Z", "A4Z") and record.trigger_index == PRE
    assert record.force_n[PRE - 1] < 20.0 <= record.force_n[PRE]
    assert record.force_n.max() == pytest.approx(500.0, rel=0.01)
    onset = int(np.argmax(blow(fs)["F"] >= 20.0))
    expected = blow(fs)["A1Z"][onset - PRE:]
    np.testing.assert_allclose(record.accel_m_per_s2[0, : expected.size], expected)
    assert record.clipped == ()
    assert hardware.tasks[-1].closed


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
    with pytest.raises(DeviceDisconnected, match="-201003"):
        daq.acquire(1.0)
    with pytest.raises(DeviceError, match="configure"):
        make(FakeNiHardware()).arm(TRIGGER)
    unarmed = make(FakeNiHardware())
    unarmed.configure(20480.0, N)
    with pytest.raises(DeviceError, match="not armed"):
        unarmed.acquire(0.1)


def test_probe_names_missing_modules() -> None:
    assert "cDAQ1Mod1, cDAQ1Mod2" in make(FakeNiHardware()).probe()
    with pytest.raises(DeviceDisconnected, match="not present: cDAQ1Mod2"):
        make(FakeNiHardware(devices=("cDAQ1Mod1",))).probe()


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
                       fake.AccelSensitivityUnits, fake.ForceIEPESensorSensitivityUnits):
        real_enum = getattr(nidaqmx.constants, enum_class.__name__)
        for member in enum_class:
            assert real_enum[member.name].value == member.value
    assert nidaqmx.errors.DaqError.__init__.__code__.co_varnames[1:4] == ("message", "error_code", "task_name")
