"""The twin's physics chain, its seating scatter, its test hooks and its determinism, seen through the instruments."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.sim import twin_of
from labctl.physics import ContactCase, load_rig, rig_modes, roller
from labctl.physics.world import load_world
from tests.test_sim_support import STEEL, bounce_and_tilt_peaks, h1, sim_rig, strike_records

RIG = load_rig()
CASE = ContactCase(roller(1), STEEL, 0.2e-6)
DEFAULT_LAW = load_world().law


def record_peaks(rig, n=2, samples=16_384):
    recs = strike_records(rig, n, samples=samples)
    freqs, frf = h1(np.stack([r.force_n for r in recs]), np.stack([r.accel_m_per_s2 for r in recs]),
                    recs[0].sample_rate_hz)
    return bounce_and_tilt_peaks(freqs, frf, list(recs[0].channels))


def test_knob_turns_to_load_to_stiffness_to_frequency():
    rig = sim_rig(seed=11)
    twin = twin_of(rig)
    spring = RIG.loading  # 180° compresses each rod's springs by half a thread pitch
    per_half_turn = spring.rods * spring.spring_rate_n_per_m * 0.5 * spring.thread_pitch_m / 3
    last_bounce = 0.0
    for half_turns in (0, 4, 10):
        rig.actuator.turn_knobs(180.0 * half_turns - rig.actuator.knob_angle_deg)
        readings = [rig.load_cell.read() for _ in range(4)]
        load = RIG.preload_per_roller_n + half_turns * per_half_turn
        assert readings[-1].stable
        assert readings[-1].force_n / 3 == pytest.approx(load, abs=1.0)
        ks = twin.roller_stiffness_n_per_m()
        # each roller follows the world's law within its seating scatter (a few % at most)
        assert np.asarray(ks) == pytest.approx(float(DEFAULT_LAW.stiffness_n_per_m(CASE, load)), rel=0.05)
        truth = rig_modes(RIG, ks)
        bounce, tilt = record_peaks(rig)
        # the blows' force swing shifts the nonlinear contact's frequency a little (most at the preload)
        shifted = np.mean([twin.blow_modes(s.blow).bounce_hz for s in twin.strikes[-2:]])
        assert shifted == pytest.approx(truth.bounce_hz, rel=0.02)
        assert bounce == pytest.approx(shifted, rel=0.005)
        assert tilt == pytest.approx(truth.tilt_hz[0], rel=0.015)
        assert bounce > last_bounce + 20
        last_bounce = bounce


@pytest.mark.parametrize("load_n, lo, hi", [(RIG.preload_per_roller_n, 0.005, 0.03), (440.0, 0.0, 0.004)])
def test_seating_scatter_is_a_few_percent_at_low_load_and_under_one_percent_high(load_n, lo, hi):
    rig = sim_rig(seed=5)
    twin = twin_of(rig)
    twin.set_load_per_roller(load_n)
    ks = []
    for _ in range(30):
        rig.operator.prompt("Lift the disc, rotate the rollers", ("done",), "rotate_rollers")
        ks.extend(twin.roller_stiffness_n_per_m())
    rel = np.std(ks) / np.mean(ks)
    assert lo < rel < hi
    assert np.mean(ks) == pytest.approx(float(DEFAULT_LAW.stiffness_n_per_m(CASE, load_n)), rel=0.01)


def test_a_hard_blow_at_low_preload_lowers_the_bounce_frequency_to_first_order():
    rig = sim_rig(seed=12)
    twin = twin_of(rig)

    def bounce(peak_n):
        twin.next_blow_peak(peak_n)
        twin.strike()
        return twin.blow_modes(twin.strikes[-1].blow).bounce_hz

    static = twin.truth()["bounce_hz"]
    soft, hard, harder = bounce(20.0), bounce(100.0), bounce(200.0)
    assert static - soft < 0.0005 * static  # a light tap measures the tangent stiffness
    assert 0.0005 * static < static - hard < 0.05 * static
    assert (static - harder) / (static - hard) == pytest.approx(4.0, rel=0.25)  # shift ∝ (force swing)²
    rec_soft, rec_hard = [], []
    for peak, out in ((50.0, rec_soft), (800.0, rec_hard)):
        twin.next_blow_peak(peak)
        out.append(record_peaks(rig, n=1)[0])
    assert rec_hard[0] < rec_soft[0]  # visible in the records themselves
    twin.set_load_per_roller(440.0)
    static = twin.truth()["bounce_hz"]
    assert static - bounce(800.0) < 0.002 * static  # negligible at high load


def test_knob_slack_after_reseating_lowers_the_load_of_a_turn_by_at_most_the_slack():
    rig = sim_rig(seed=13)
    twin = twin_of(rig)
    per_deg = RIG.load_per_knob_degree_n
    loads = []
    for _ in range(6):
        rig.actuator.turn_knobs(-rig.actuator.knob_angle_deg)
        rig.operator.prompt("Lift the disc, rotate the rollers", ("done",), "rotate_rollers")
        rig.actuator.turn_knobs(1800)
        loads.append(twin.load_per_roller_n())
    nominal = RIG.preload_per_roller_n + 1800 * per_deg
    slack = twin.settings.knob_slack_deg
    assert slack > 0
    assert all(nominal - slack * per_deg <= x <= nominal for x in loads)
    assert np.ptp(loads) > 0.1 * slack * per_deg


def test_impacts_vary_in_force_width_and_point():
    rig = sim_rig(seed=2)
    recs = strike_records(rig, 4, samples=4096)
    peaks = [r.force_n.max() for r in recs]
    assert np.std(peaks) / np.mean(peaks) > 0.03
    blows = [s.blow for s in twin_of(rig).strikes]
    assert len({round(b.width_s, 9) for b in blows}) == 4
    assert all(0.2e-3 <= b.width_s <= 0.5e-3 for b in blows)
    points = np.array([(b.x_m, b.y_m) for b in blows])
    assert np.all(np.hypot(*(points - RIG.hammer_xy_m).T) < 0.02)
    assert len({tuple(p) for p in points}) == 4
    assert all(abs(r.timestamp_s - recs[0].timestamp_s) < 60 for r in recs)
    assert [r.timestamp_s for r in recs] == sorted(r.timestamp_s for r in recs)


def test_double_hit_hook_adds_a_second_pulse():
    rig = sim_rig(seed=3)
    twin_of(rig).next_blow_double(delay_s=2e-3, ratio=0.5)
    double, clean = strike_records(rig, 2, samples=4096)
    fs = double.sample_rate_hz
    after = int(double.trigger_index + 1.2e-3 * fs)
    second = double.force_n[after:after + int(2e-3 * fs)].max()
    assert second == pytest.approx(0.5 * double.force_n.max(), rel=0.15)
    assert clean.force_n[after:after + int(2e-3 * fs)].max() < 5.0  # the hook acts on one blow only


@pytest.mark.parametrize("channel", ["F", "A2Z"])
def test_overload_hook_clips_the_channel_at_its_range(channel):
    rig = sim_rig(seed=4)
    twin_of(rig).next_blow_overload(channel)
    over, normal = strike_records(rig, 2, samples=4096)
    rng = {c.name: c.range_units for c in rig.daq.channels}
    assert channel in over.clipped and normal.clipped == ()
    signal = over.force_n if channel == "F" else over.accel_m_per_s2[list(over.channels).index(channel)]
    assert np.max(np.abs(signal)) == pytest.approx(rng[channel])


def test_dead_channel_records_noise_only():
    rig = sim_rig(seed=5)
    twin_of(rig).kill_channel("A3Y")
    rec = strike_records(rig, 1, samples=4096)[0]
    rms = np.sqrt(np.mean(rec.accel_m_per_s2**2, axis=1))
    dead = list(rec.channels).index("A3Y")
    assert rms[dead] < 0.01 < np.median(rms)
    with pytest.raises(ValueError, match="unknown channel"):
        twin_of(rig).kill_channel("A9Z")


def test_the_seed_makes_everything_reproducible():
    def run(seed):
        rig = sim_rig(seed=seed)
        twin = twin_of(rig)
        rig.actuator.turn_knobs(540)
        reads = [rig.load_cell.read().force_n for _ in range(3)]
        rig.operator.prompt("rotate", ("done",), "rotate_rollers")
        rec = strike_records(rig, 2, samples=2048)
        return reads, twin.truth(), np.stack([r.force_n for r in rec]), np.stack([r.accel_m_per_s2 for r in rec])

    a, b, c = run(21), run(21), run(22)
    assert a[0] == b[0] and a[1] == b[1]
    np.testing.assert_array_equal(a[2], b[2])
    np.testing.assert_array_equal(a[3], b[3])
    assert a[1]["roller_stiffness_n_per_m"] != c[1]["roller_stiffness_n_per_m"]
    assert not np.array_equal(a[3], c[3])


def test_extra_load_cell_reads_do_not_change_the_impact_data():
    def accel(extra_reads):
        rig = sim_rig(seed=8)
        for _ in range(extra_reads):
            rig.load_cell.read()
        return strike_records(rig, 1, samples=2048)[0].accel_m_per_s2

    np.testing.assert_array_equal(accel(0), accel(5))


def test_seating_scatter_comes_from_the_asperities_the_spot_meets_and_nothing_else(tmp_path):
    from labctl.physics.world import data_path

    text = data_path("worlds/default.toml").read_text()
    world = tmp_path / "no_spot.toml"
    world.write_text(text.replace("asperity_spot_rel = 0.18", "asperity_spot_rel = 0.0"))
    twin = twin_of(sim_rig(seed=5, world=str(world)))
    twin.set_load_per_roller(RIG.preload_per_roller_n)
    ks = set()
    for _ in range(5):
        twin.rotate_rollers()
        ks.update(round(k, 6) for k in twin.roller_stiffness_n_per_m())
    assert len(ks) == 1  # no multiplicative noise term: without the seating spots every roller is the same
