"""The NI path through the engine: quick_check asks for 20 480 Hz × 65 536 samples (3.2 s); on an NI 9234 (fake
DAQmx task, 51.2 kS/s ÷ n) the campaign records 3.2 s at the rate the module sets, stores that rate, and the
identification on those records agrees with the all-simulated run — at 25 600 Hz (rate coerced up) and at
17 066.7 Hz (coerced to the nearest)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from drivers.interfaces import Rig, TriggerSpec
from drivers.sim import SimSettings
from labctl import campaign
from labctl.backends import make_rig as make_sim_or_hw_rig
from labctl.hardware import make_hw_rig
from labctl.protocol import load_protocol
from tests.emulators.fake_nidaqmx import FakeNiHardware
from tests.emulators.instruments import HammerDevice
from tests.emulators.pty_serial import PtySerialEmulator

PROTOCOL = Path(__file__).resolve().parents[1] / "protocols" / "quick_check.toml"
SEED = 11
G = 9.80665
NAMES = ["F", *(f"A{i}{axis}" for i in range(1, 5) for axis in "XYZ")]  # 13 channels on 4 × NI 9234


def devices_toml(load_port: str, hammer_port: str) -> str:
    s = SimSettings()
    rows = []
    for i, name in enumerate(NAMES):
        where = f'"cDAQ1Mod{i // 4 + 1}/ai{i % 4}"'
        if name == "F":
            rows.append(f'[[daq.channels]]\nname = "F"\nkind = "force"\ninput = {where}\n'
                        f"sensitivity_mv_per_n = {s.force_sensitivity_v_per_n * 1e3!r}\nrange_n = 2000.0\n")
        else:
            rows.append(f'[[daq.channels]]\nname = "{name}"\nkind = "acceleration"\ninput = {where}\n'
                        f"sensitivity_mv_per_g = {s.accel_sensitivity_v_per_m_per_s2 * 1e3 * G!r}\n"
                        f"range_g = {s.accel_range_m_per_s2 / G!r}\n")
    return (f'[load_cell]\ntype = "mtsics"\nport = "{load_port}"\n\n[daq]\ntype = "nidaqmx"\n\n' + "\n".join(rows)
            + f'\n[hammer]\ntype = "serial"\nport = "{hammer_port}"\nlevel = 100\nboot_delay_s = 0\n\n'
            + '[actuator]\ntype = "manual"\nknobs = 4\n')


class NiTwin:
    """Real NI adapter, MT-SICS load cell and serial hammer; the fake chassis plays the simulated rig's response
    sampled at the rate the module runs at."""

    def __init__(self, tmp_path: Path, rule: str) -> None:
        acq = load_protocol(PROTOCOL).acquisition
        self.hardware = FakeNiHardware(rate_rule=rule)
        self.rate_hz = self.hardware.coerce_rate(acq.sample_rate_hz)
        self.samples = round(acq.samples / acq.sample_rate_hz * self.rate_hz)
        pre = round(acq.pretrigger_samples * self.rate_hz / acq.sample_rate_hz)
        self.trigger = TriggerSpec(acq.trigger_level_n, pre)
        self.sim: Rig | None = None
        self.cell = PtySerialEmulator(self._sics).__enter__()
        self.hammer = PtySerialEmulator(HammerDevice(on_fire=self._blow)).__enter__()
        self.devices = tmp_path / "devices.toml"
        self.devices.write_text(devices_toml(self.cell.port, self.hammer.port), encoding="utf-8")

    def make_rig(self, backend: str, **kw: Any) -> Rig:
        assert backend == "hw" and kw["devices"] == self.devices
        self.sim = make_sim_or_hw_rig("sim", **{**kw, "devices": None})
        self.sim.daq.configure(self.rate_hz, self.samples)
        rig = make_hw_rig(self.devices, operator=self.sim.operator, nidaqmx_module=self.hardware.module())
        return replace(rig, actuator=self.sim.actuator)

    def _sics(self, command: str) -> str:
        assert self.sim is not None
        if command == "SI":
            reading = self.sim.load_cell.read()
            return f"S {'S' if reading.stable else 'D'} {reading.force_n:>10.2f} N"
        return 'I4 A "B947123456"' if command in ("I4", "@") else "ES"

    def _blow(self, level: int) -> None:
        assert self.sim is not None
        self.sim.daq.arm(self.trigger)
        self.sim.hammer.strike()
        record = self.sim.daq.acquire(1.0)
        self.hardware.blow({"F": record.force_n, **dict(zip(record.channels, record.accel_m_per_s2, strict=True))})

    def stop(self) -> None:
        self.cell.stop()
        self.hammer.stop()


@pytest.fixture(scope="module")
def sim_run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    out = tmp_path_factory.mktemp("sim") / "sim.h5"
    result = campaign.run_campaign(PROTOCOL, out=out, backend="sim", seed=SEED)
    assert result.status == "complete", result.message
    return result.curves[0]


@pytest.fixture
def twin(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[NiTwin]:
    bench = NiTwin(tmp_path, request.param)
    yield bench
    bench.stop()


@pytest.mark.parametrize(("twin", "rate", "samples"), [("up", 25600.0, 81920), ("nearest", 51200.0 / 3, 54613)],
                         indirect=["twin"])
def test_quick_check_on_the_ni_path_records_3_2_s_at_the_modules_rate(
        tmp_path: Path, twin: NiTwin, rate: float, samples: int, sim_run: dict[str, Any],
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(campaign, "make_rig", twin.make_rig)
    out = tmp_path / "ni.h5"
    hw = campaign.run_campaign(PROTOCOL, out=out, backend="hw", seed=SEED, devices=twin.devices)
    assert hw.status == "complete", hw.message
    task = twin.hardware.tasks[-1]
    assert task.timing.samp_clk_rate == pytest.approx(rate) and task.timing.samps_per_chan == samples
    assert all(c.ai_coupling.name == "AC" for c in task.ai_channels.added)
    with h5py.File(out, "r") as f:  # every stored impact: the module's rate, 3.2 s, the 12.5 ms pretrigger
        impacts = []
        f.visititems(lambda name, obj: impacts.append(obj) if isinstance(obj, h5py.Group)
                     and "trigger_index" in obj.attrs else None)
        assert impacts
        for group in impacts:
            assert float(group.attrs["sample_rate_hz"]) == pytest.approx(rate)
            assert int(group.attrs["trigger_index"]) == round(256 * rate / 20480.0)
    h, s = hw.curves[0], sim_run
    assert len(h["load_n"]) == len(s["load_n"]) >= 2
    np.testing.assert_allclose(h["load_n"], s["load_n"], atol=0.01)
    # the same twin sampled at another rate over the same 3.2 s (other noise draws, another filter): the identified
    # contact agrees within the impact-to-impact spread the run itself reports (k ∝ f², so f within half of it);
    # a rate stored wrongly (25 600 Hz data read as 20 480 Hz) would move every frequency by 20 %
    spread = np.asarray(s["stiffness_std_n_per_m"]) / np.asarray(s["stiffness_n_per_m"])
    assert np.all(spread < 0.05)
    np.testing.assert_array_less(np.abs(np.asarray(h["stiffness_n_per_m"]) / s["stiffness_n_per_m"] - 1), 2 * spread)
    np.testing.assert_array_less(np.abs(np.asarray(h["bounce_hz"]) / s["bounce_hz"] - 1), spread)
