"""Single-impact checks: each reason with positive and negative cases, on synthetic blows with known truth."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from labctl.processing import CheckConfig, check_impact
from tests.synth_impacts import load_rig, rig_truth_modes, synth_impacts

RIG = load_rig()
ONE = ("A1Z",)
MODES_1 = rig_truth_modes(RIG, 4.65e7, ONE)
N = 16384


def one_channel(**kw):
    return synth_impacts(MODES_1, ONE, n_samples=N, **kw)


def verdicts(s, **kw):
    return [check_impact(s.force_n[i], s.accel_m_per_s2[i], s.fs_hz, index=i, **kw) for i in range(len(s.force_n))]


def fir_ringing(s):
    """A linear-phase anti-alias FIR (as in sigma-delta DAQs): rings before and after the blow."""
    taps = signal.firwin(127, 0.45 * s.fs_hz, fs=s.fs_hz)
    s.force_n = signal.fftconvolve(s.force_n, taps[None, :], mode="same", axes=-1)
    s.accel_m_per_s2 = signal.fftconvolve(s.accel_m_per_s2, taps[None, None, :], mode="same", axes=-1)
    return s


@pytest.mark.parametrize("snr_db", [30.0, 40.0, 60.0])
@pytest.mark.parametrize("filtering", ["none", "iir", "fir"])
def test_clean_impacts_are_never_rejected(snr_db, filtering):
    for seed in range(6):
        s = one_channel(snr_db=snr_db, seed=seed, ringing=filtering == "iir",
                        pulse_s=[2e-4, 3.5e-4, 5e-4], peak_force_n=[80.0, 300.0, 900.0])
        if filtering == "fir":
            s = fir_ringing(s)
        for c in verdicts(s):
            assert c.accepted, (seed, c)
            assert c.reasons == ()
            assert c.second_hit_ratio < 0.03


@pytest.mark.parametrize("delay_s, ratio", [(1e-3, 0.5), (5e-3, 0.3), (20e-3, 0.1)])
@pytest.mark.parametrize("pulse_s", [2e-4, 5e-4])
@pytest.mark.parametrize("filtering", ["none", "iir", "fir"])
def test_second_hits_are_rejected_as_double_hit(delay_s, ratio, pulse_s, filtering):
    s = one_channel(snr_db=30.0, seed=3, pulse_s=pulse_s, double_hits={0: (delay_s, ratio), 2: (delay_s, ratio)},
                    ringing=filtering == "iir")
    if filtering == "fir":
        s = fir_ringing(s)
    first, clean, last = verdicts(s)
    for c in (first, last):
        assert c.reasons == ("double_hit",), c
        assert c.second_hit_ratio == pytest.approx(ratio, abs=0.2 * ratio)
        assert c.second_hit_delay_s == pytest.approx(delay_s, abs=0.2e-3)
    assert clean.accepted


def test_a_second_hit_below_the_sensitivity_is_tolerated_and_reported():
    s = one_channel(snr_db=40.0, seed=1, double_hits={1: (5e-3, 0.02)})
    c = verdicts(s)[1]
    assert c.accepted
    assert c.second_hit_ratio == pytest.approx(0.02, abs=0.006)
    stricter = verdicts(s, config=CheckConfig(double_hit_ratio=0.01))[1]
    assert stricter.reasons == ("double_hit",)


def test_a_hit_before_the_main_one_is_a_double_hit():
    s = one_channel(snr_db=40.0, seed=2, pretrigger=600)
    pre = np.roll(s.force_n[0], -80) * 0.4  # a lighter touch 80 samples (3.9 ms) before the blow
    s.force_n[0] += np.where(np.arange(N) < 560, pre, 0.0)
    c = verdicts(s)[0]
    assert "double_hit" in c.reasons
    assert c.second_hit_delay_s < 0


def test_overload_with_known_ranges_names_the_channel():
    s = synth_impacts(rig_truth_modes(RIG, 4.65e7), RIG.channels, n_samples=N, seed=4)
    peaks = np.abs(s.accel_m_per_s2[0]).max(axis=-1)
    ranges = peaks / 0.9  # every channel at 90 % of its range: fine
    assert check_impact(s.force_n[0], s.accel_m_per_s2[0], s.fs_hz, accel_ranges=ranges, channels=RIG.channels,
                        force_range_n=2200.0).accepted
    ranges[5] = peaks[5] / 0.96  # A2Z at 96 %
    c = check_impact(s.force_n[0], s.accel_m_per_s2[0], s.fs_hz, accel_ranges=ranges, channels=RIG.channels,
                     force_range_n=2200.0)
    assert c.reasons == ("overload",)
    assert c.overloaded == ("A2Z",)
    f = check_impact(s.force_n[0], s.accel_m_per_s2[0], s.fs_hz, accel_ranges=peaks / 0.5,
                     force_range_n=0.9 * float(s.force_n[0].max()))
    assert f.overloaded == ("force",)


def test_overload_without_ranges_is_seen_as_a_clipped_plateau():
    s = one_channel(snr_db=40.0, seed=5)
    level = 0.6 * float(np.abs(s.accel_m_per_s2[1, 0]).max())
    s.accel_m_per_s2[1, 0] = np.clip(s.accel_m_per_s2[1, 0], -level, level)
    clean, clipped, _ = verdicts(s)
    assert clean.accepted
    assert clipped.reasons == ("overload",)


def test_a_clipped_response_channel_other_than_the_first_is_caught():
    for seed in range(4):
        s = synth_impacts(rig_truth_modes(RIG, 4.65e7), RIG.channels, n_samples=8192, seed=30 + seed, n_impacts=1)
        c = RIG.channels.index("A2Z")
        level = 0.6 * float(np.abs(s.accel_m_per_s2[0, c]).max())
        s.accel_m_per_s2[0, c] = np.clip(s.accel_m_per_s2[0, c], -level, level)
        check = check_impact(s.force_n[0], s.accel_m_per_s2[0], s.fs_hz, channels=RIG.channels)
        assert check.overloaded == ("A2Z",), (seed, check)


def _lateral_response(equal_top: bool) -> np.ndarray:
    """A small lateral channel on a 24-bit ±490 m/s² input: a 745 Hz ring-down of 0.26 m/s² from sample
    300, in ADC steps (noise below one step). ``equal_top`` places its first crest midway between two
    samples, so that both round to the same step."""
    fs, lsb, w, a = 20480.0, 490.0 / 2**23, 2 * np.pi * 745.0, 40.0
    crest_s = np.arctan(w / a) / w  # first maximum of exp(-a t) sin(w t)
    start = 300 + (np.ceil(crest_s * fs) + 0.5 - crest_s * fs if equal_top else 0.3)
    t = (np.arange(8192) - start) / fs
    x = 0.26 / np.exp(-a * crest_s) * np.exp(-a * t) * np.sin(w * t) * (t > 0)
    x += np.random.default_rng(3).normal(0.0, 0.2 * lsb, t.size)
    return np.round(x / lsb) * lsb


def _blow(n: int) -> np.ndarray:
    t = (np.arange(n) - 294.5) / 20480.0
    pulse = 250.0 * np.sin(np.pi * np.clip(t, 0, 2.5e-4) / 2.5e-4)
    return pulse + np.random.default_rng(4).normal(0.0, 0.5, n)


def test_a_natural_peak_sampled_twice_alike_is_not_an_overload():
    """Two samples straddling a crest may round to one ADC step: ~1 in 200 blows of a small channel on a
    24-bit input. Far above the step is not enough to call that a clip; the drop to the neighbours decides."""
    x = _lateral_response(True)
    at = np.flatnonzero(x == x.max())
    assert len(at) == 2 and x.max() / (490.0 / 2**23) > 4096  # the case: two hits, thousands of steps up
    force = _blow(x.size)
    check = check_impact(force, x[None, :], 20480.0, channels=("A2Y",))
    assert check.overloaded == (), check


def test_a_noise_free_force_resting_at_zero_is_not_an_overload():
    """A synthetic or pre-windowed force: exactly 0 outside the pulse, its minimum reached thousands of times."""
    x = _lateral_response(False)
    force = np.clip(_blow(x.size), 0.0, None)
    force[force < 2.0] = 0.0
    check = check_impact(force, x[None, :], 20480.0, channels=("A2Y",))
    assert check.overloaded == (), check


@pytest.mark.parametrize("samples", [3, 4])
def test_a_flat_top_of_a_few_adc_steps_is_an_overload(samples):
    """The same channel clipped (by an amplifier below the stated range) over its top few samples."""
    x = _lateral_response(False)
    x = np.minimum(x, np.sort(x)[-samples])
    force = _blow(x.size)
    check = check_impact(force, x[None, :], 20480.0, channels=("A2Y",))
    assert check.overloaded == ("A2Y",), check


def test_a_small_quantised_signal_repeating_its_peak_is_not_an_overload():
    s = one_channel(snr_db=60.0, seed=6)
    x = s.accel_m_per_s2[0, 0]
    lsb = float(np.abs(x).max()) / 20.0  # only ~20 steps of a coarse ADC
    s.accel_m_per_s2[0, 0] = np.round(x / lsb) * lsb
    assert verdicts(s)[0].accepted


@pytest.mark.parametrize("pulse_s, ok", [(0.05e-3, False), (0.15e-3, True), (0.9e-3, True), (1.5e-3, False)])
def test_pulse_width_outside_the_tip_range_is_rejected(pulse_s, ok):
    s = one_channel(snr_db=40.0, seed=7, pulse_s=pulse_s)
    c = verdicts(s)[0]
    assert c.accepted is ok, c
    if not ok:
        assert c.reasons == ("pulse_width",)
    if pulse_s >= 0.15e-3:
        assert c.pulse_width_s == pytest.approx(pulse_s, rel=0.12)


def test_low_force_and_no_blow_are_rejected():
    s = one_channel(snr_db=40.0, seed=8, peak_force_n=[5.0, 50.0, 300.0])
    weak, fine, strong = verdicts(s)
    assert weak.reasons == ("low_force",)
    assert fine.accepted and strong.accepted
    assert strong.peak_force_n == pytest.approx(300.0, rel=0.02)
    noise = np.random.default_rng(0).normal(0.0, 0.05, N)
    nothing = check_impact(noise, s.accel_m_per_s2[0], s.fs_hz)
    assert "low_force" in nothing.reasons


def test_a_force_channel_wired_negative_still_checks_the_blow():
    s = one_channel(snr_db=40.0, seed=9)
    c = check_impact(-s.force_n[0], s.accel_m_per_s2[0], s.fs_hz)
    assert c.accepted and c.polarity == -1.0
    assert c.peak_force_n == pytest.approx(float(s.force_n[0].max()), rel=0.02)


def test_bad_configuration_and_shapes_are_refused():
    with pytest.raises(ValueError, match="double_hit_ratio"):
        CheckConfig(double_hit_ratio=1.5)
    with pytest.raises(ValueError, match="pulse width"):
        CheckConfig(pulse_width_min_s=1e-3, pulse_width_max_s=1e-4)
    with pytest.raises(ValueError, match="expected"):
        check_impact(np.zeros(100), np.zeros((2, 99)), 20480.0)
