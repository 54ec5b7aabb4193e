"""Faults of the training world: each is generated inside the simulated instruments as its world configures it,
and the engine and the processing catch it (or survive it) on the same code path as hardware."""

from __future__ import annotations

import re

import h5py
import numpy as np
import pytest

from drivers.errors import DeviceError, DeviceTimeout
from drivers.sim import twin_of
from labctl import events as ev
from labctl.errors import InputError
from labctl.physics.world import data_path
from tests.test_sim_support import sim_rig, strike_records

TRAINING = data_path("worlds/training.toml")


def faults_world(tmp_path, **rates: float) -> str:
    """The default world with only the given faults (name → value, SI)."""
    text = data_path("worlds/default.toml").read_text()
    text += "\n[faults]\n" + "".join(f"{k} = {v!r}\n" for k, v in rates.items())
    path = tmp_path / "faults.toml"
    path.write_text(text)
    return str(path)


def test_training_world_turns_every_fault_on_and_bad_fault_settings_are_refused(tmp_path):
    from labctl.backends import fault_settings
    from labctl.physics.world import load_world

    f = fault_settings(load_world("training"))
    assert f.double_hit_rate > 0 and f.late_double_hit_rate > 0 and f.overload_rate > 0
    assert f.intermittent_channel_rate > 0 and f.dead_channel_rate > 0 and f.mains_hum_m_per_s2 > 0
    assert f.creep_rate > 0 and f.load_cell_timeout_rate > 0 and f.load_cell_garbled_rate > 0
    assert f.unequal_seating_rate > 0 and f.unequal_seating_gap_m == pytest.approx(0.5e-6)
    for rates, message in [
        ({"double_hit_rate": 2.0}, "faults: fault setting double_hit_rate = 2.0: expected a probability in [0, 1]"),
        ({"double_hit_rat": 0.1}, "faults: unknown key(s) double_hit_rat (did you mean 'double_hit_rate'?); expected"),
        ({"hum": 1.0}, "faults: unknown key(s) hum; expected one of creep_n_per_s, creep_rate"),
    ]:
        path = faults_world(tmp_path, **rates)
        with pytest.raises(InputError) as exc:
            sim_rig(world=path)
        assert path in str(exc.value) and message in str(exc.value)


def test_double_hits_come_at_their_rate_and_sizes(tmp_path):
    twin = twin_of(sim_rig(seed=3, world=faults_world(tmp_path, double_hit_rate=0.2, late_double_hit_rate=0.1)))
    blows = [twin.strike().blow for _ in range(400)]
    early = [b for b in blows if b.second_ratio >= 0.2]
    late = [b for b in blows if 0 < b.second_ratio < 0.2]
    assert abs(len(early) - 80) < 3 * np.sqrt(400 * 0.2 * 0.8) and abs(len(late) - 40) < 3 * np.sqrt(400 * 0.09)
    assert all(1e-3 <= b.second_delay_s <= 3e-3 and b.second_ratio <= 0.6 for b in early)
    assert all(2e-3 <= b.second_delay_s <= 10e-3 and 0.01 <= b.second_ratio <= 0.05 for b in late)
    assert sum("double hit" in what for _, what in twin.fault_log) == len(early) + len(late)


def test_small_late_second_hit_is_in_the_force_record(tmp_path):
    rig = sim_rig(seed=4, world=faults_world(tmp_path, late_double_hit_rate=1.0))
    rec = strike_records(rig, 1, samples=4096)[0]
    blow = twin_of(rig).strikes[-1].blow
    fs, i0 = rec.sample_rate_hz, rec.trigger_index
    start = i0 + int((blow.second_delay_s - 0.1e-3) * fs)
    second = rec.force_n[start:start + int(blow.width_s * fs) + 4].max()
    assert second == pytest.approx(blow.second_ratio * blow.peak_n, rel=0.25, abs=1.0)


def test_overload_dropout_pulled_cable_and_hum_act_on_the_records(tmp_path):
    world = faults_world(tmp_path, overload_rate=1.0, intermittent_channel_rate=1.0, mains_hum_m_per_s2=0.05)
    rig = sim_rig(seed=5, world=world)
    recs = strike_records(rig, 3, samples=8192)
    for rec in recs:
        assert rec.clipped  # one channel past its range every blow
        flat = [ch for ch, a in zip(rec.channels, rec.accel_m_per_s2, strict=True) if not np.any(a)]
        assert len(flat) == 1  # one connector out for this record
        live = rec.accel_m_per_s2[[i for i, ch in enumerate(rec.channels) if ch not in flat]]
        spectrum = np.abs(np.fft.rfft(live[:, -4096:], axis=1)) * 2 / 4096
        freqs = np.fft.rfftfreq(4096, 1 / rec.sample_rate_hz)
        hum = spectrum[:, np.argmin(np.abs(freqs - 50.0))]
        assert np.all(hum > 0.015)  # 0.05 m/s² × a cable gain of 0.5-1 (± leakage)
    rig = sim_rig(seed=6, world=faults_world(tmp_path, dead_channel_rate=1.0))
    twin = twin_of(rig)
    rig.operator.prompt("rotate", ("done",), "rotate_rollers")
    pulled = twin.pulled_channel
    for rec in strike_records(rig, 2, samples=2048):
        assert not np.any(rec.accel_m_per_s2[list(rec.channels).index(pulled)])


def test_creep_starts_with_the_blows_after_a_turn(tmp_path):
    rig = sim_rig(seed=7, world=faults_world(tmp_path, creep_rate=1.0, creep_n_per_s=-2.0))
    twin = twin_of(rig)
    rig.actuator.turn_knobs(360)
    before = twin.load_per_roller_n()
    [rig.load_cell.read() for _ in range(5)]
    assert twin.load_per_roller_n() == pytest.approx(before)  # nothing creeps until the hammer shakes the nut
    strike_records(rig, 2, samples=20480)  # 1 s of record each
    assert twin.load_per_roller_n() == pytest.approx(before - 2.0 * 2.0, abs=0.5)


def test_load_cell_timeouts_and_garbled_replies(tmp_path):
    for rate, error in (("load_cell_timeout_rate", DeviceTimeout), ("load_cell_garbled_rate", DeviceError)):
        rig = sim_rig(seed=8, world=faults_world(tmp_path, **{rate: 1.0}))
        with pytest.raises(error) as exc:
            rig.load_cell.read()
        assert exc.type is error and "sim-loadcell" in str(exc.value)


def test_a_roller_on_a_burr_is_softer_and_splits_the_tilt_pair(tmp_path):
    rig = sim_rig(seed=9, world=faults_world(tmp_path, unequal_seating_rate=1.0, unequal_seating_gap_um=1.0))
    twin = twin_of(rig)
    twin.set_load_per_roller(60.0)
    ks = sorted(twin.roller_stiffness_n_per_m())
    assert ks[0] < 0.8 * ks[1]  # 1 µm/60 N of extra compliance on one roller
    tilt = twin.truth()["tilt_hz"]
    assert abs(tilt[1] - tilt[0]) > 5.0


@pytest.mark.slow
def test_engine_and_processing_catch_the_faults_and_reprocessing_agrees(tmp_path):
    from labctl.campaign import run_campaign
    from labctl.protocol import load_protocol
    from labctl.reprocess import process_campaign

    text = TRAINING.read_text()
    for key, value in {"double_hit_rate": 0.4, "creep_rate": 1.0, "dead_channel_rate": 1.0,
                       "load_cell_timeout_rate": 0.3}.items():
        text = re.sub(rf"^{key} = [0-9.]+", f"{key} = {value}", text, flags=re.M)
    world = tmp_path / "busy_training.toml"
    world.write_text(text)
    events: list[ev.Event] = []
    path = tmp_path / "c.h5"
    outcome = run_campaign(load_protocol("protocols/quick_check.toml"), out=path, backend="sim", seed=1,
                           world=str(world), subscribers=[events.append])
    assert outcome.status == "complete"
    assert any("load cell" in e.message and "retrying" in e.message for e in events if isinstance(e, ev.Notice))
    assert any("drifted" in e.reason for e in events if isinstance(e, ev.Suspended))
    reasons, dead, drift, live = [], set(), 0, {}
    with h5py.File(path) as f:
        for name, step in f["series_01/run_01"].items():
            if not name.startswith("step_"):
                continue
            drift += bool(step.attrs.get("load_drift", False))
            reasons += [str(g.attrs["reasons"]) for k, g in step.items() if k.startswith("impact_")]
            if "result" in step:
                dead.update(re.findall(r"A\d[XYZ]", str(step["result"].attrs["dead_channels"])))
                live[int(step.attrs["step"])] = float(step["result"].attrs["roller_stiffness_n_per_m"])
    assert any("double_hit" in r for r in reasons)  # rejected and hit again
    assert len(dead) == 1  # the pulled cable is left out of the identification
    assert drift >= 1  # the step that crept is marked
    again = {r.step: r.result.roller_stiffness_n_per_m for r in process_campaign(path).rows if r.result.identified}
    assert again == pytest.approx(live, rel=1e-9)
