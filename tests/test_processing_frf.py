"""H1/H2/coherence against an analytic single-mode system, the windows, and the window's damping removed."""

from __future__ import annotations

import math

import numpy as np
import pytest

from labctl.errors import InputError
from labctl.processing.checks import locate_pulse
from labctl.processing.frf import (
    MIN_SPAN_S,
    WindowConfig,
    analysed_samples,
    blow_spectra,
    estimate_frf,
    force_window,
    impact_spectra,
    ring_down_samples,
)
from labctl.processing.modes import fit_modes
from tests.synth_impacts import SynthMode, accelerance, synth_impacts

F0, ZETA = 745.0, 0.02
RESIDUE = np.array([0.04, -0.01])
SINGLE = [SynthMode("bounce", F0, ZETA, RESIDUE)]
CHANNELS = ("A1Z", "A4Z")


def spectra_of(s, window: WindowConfig):
    pulses = [(p.start, p.end, p.noise_n) for p in (locate_pulse(f, s.fs_hz) for f in s.force_n)]
    return impact_spectra(s.force_n, s.accel_m_per_s2, s.fs_hz, pulses, window)


@pytest.fixture(scope="module")
def clean():
    return synth_impacts(SINGLE, CHANNELS, n_samples=32768, snr_db=200.0, seed=1)


def test_h1_equals_the_analytic_accelerance_without_window(clean):
    sp = spectra_of(clean, WindowConfig(exponential_end=None))
    frf = estimate_frf(sp, [0, 1, 2])
    band = (frf.frequencies_hz > 100) & (frf.frequencies_hz < 3000)
    exact = accelerance(SINGLE, frf.frequencies_hz[band])
    err = np.abs(frf.h1[:, band] - exact) / np.abs(exact).max(axis=1, keepdims=True)
    assert err.max() < 2e-4
    assert np.abs(frf.h2[:, band] - exact).max() / np.abs(exact).max() < 2e-4
    assert frf.coherence[:, band].min() > 0.9999


def test_the_exponential_window_shifts_the_pole_by_its_rate(clean):
    cfg = WindowConfig(exponential_end=0.01)
    sp = spectra_of(clean, cfg)
    a = cfg.decay_rate_per_s(32768, clean.fs_hz)
    assert sp.decay_rate_per_s == pytest.approx(a)
    assert a == pytest.approx(math.log(100.0) * clean.fs_hz / 32767)
    frf = estimate_frf(sp, [0, 1, 2])
    band = (frf.frequencies_hz > 400) & (frf.frequencies_hz < 1100)
    s = 2j * np.pi * frf.frequencies_hz[band] + a  # H(iω + a): the windowed FRF
    w = 2 * np.pi * F0
    shifted = np.outer(RESIDUE, s**2 / (s**2 + 2 * ZETA * w * s + w**2))
    assert np.abs(frf.h1[:, band] - shifted).max() / np.abs(shifted).max() < 1e-3


def test_the_fit_removes_the_windows_added_damping_exactly(clean):
    cfg = WindowConfig(exponential_end=0.001)  # a strong window: about +5 % damping if left in
    sp = spectra_of(clean, cfg)
    frf = estimate_frf(sp, [0, 1, 2])
    band = (frf.frequencies_hz > 600) & (frf.frequencies_hz < 900)
    f, h = frf.frequencies_hz[band], frf.h1[:, band]
    corrected = fit_modes(f, h, [(740.0, 0.03)], decay_rate_per_s=sp.decay_rate_per_s)
    naive = fit_modes(f, h, [(740.0, 0.03)], decay_rate_per_s=0.0)
    assert corrected.frequencies_hz[0] == pytest.approx(F0, abs=1e-3)
    assert corrected.damping_ratios[0] == pytest.approx(ZETA, rel=1e-4)
    added = sp.decay_rate_per_s / (2 * np.pi * F0)
    assert naive.damping_ratios[0] == pytest.approx(ZETA + added, rel=2e-3)
    assert added / ZETA > 0.04


def test_noise_lowers_coherence_and_h2_overestimates():
    s = synth_impacts(SINGLE, CHANNELS, n_samples=32768, snr_db=0.0, seed=2, n_impacts=4)
    frf = estimate_frf(spectra_of(s, WindowConfig(trim_to_decay=False)), [0, 1, 2, 3])
    far = (frf.frequencies_hz > 2000) & (frf.frequencies_hz < 2900)
    near = np.abs(frf.frequencies_hz - F0) < 3
    assert frf.coherence[0, near].min() > 0.98
    assert frf.coherence[0, far].mean() < 0.9
    assert np.mean(np.abs(frf.h2[0, far])) > np.mean(np.abs(frf.h1[0, far]))


def test_force_window_keeps_the_blow_and_what_stands_above_the_noise():
    cfg = WindowConfig(force_pre_s=0.5e-3, force_post_s=2e-3, taper_s=0.25e-3, force_noise_sigmas=4.0)
    rng = np.random.default_rng(3)
    f = rng.normal(0.0, 0.01, 4096)
    f[300:307] += 100.0 * np.sin(np.pi * np.arange(1, 8) / 8)
    lo, w = force_window(f, 20480.0, 300, 306, 0.01, cfg)
    taper = round(0.25e-3 * 20480)
    assert lo == 299 - taper and len(w) == 2 * taper + 9  # the pulse and one sample either side
    assert np.all(w[taper:-taper] == 1.0)
    assert np.all(np.diff(w[:taper]) > 0) and np.all(np.diff(w[-taper:]) < 0)
    ringing = f.copy()
    ringing[307:327] += 2.0 * np.cos(np.pi * 0.9 * np.arange(20)) * np.exp(-np.arange(20) / 6)
    lo2, w2 = force_window(ringing, 20480.0, 300, 306, 0.01, cfg)
    assert lo2 == lo and lo2 + len(w2) > lo + len(w) + 10  # the window follows the ringing
    far = f.copy()
    far[306 + 200] = 5.0  # beyond force_post_s: not part of the blow's window
    assert len(force_window(far, 20480.0, 300, 306, 0.01, cfg)[1]) == len(w)


def test_spectra_stop_at_the_configured_frequency(clean):
    sp = spectra_of(clean, WindowConfig(max_frequency_hz=2000.0))
    assert sp.frequencies_hz[-1] <= 2000.0 < sp.frequencies_hz[-1] + clean.fs_hz / 32768 * 1.01
    assert sp.response.shape == (3, 2, len(sp.frequencies_hz))


def test_blow_spectra_of_raw_blows_give_the_analytic_frf_and_the_same_estimate_as_located_pulses(clean):
    """The per-hit gate's FRF of blows not yet identified: pulses found by the checks, one blow or several."""
    plain = WindowConfig(exponential_end=None)
    sp = blow_spectra(clean.force_n, clean.accel_m_per_s2, clean.fs_hz, cfg=plain)
    frf = estimate_frf(sp, [0, 1, 2])
    band = (frf.frequencies_hz > 100) & (frf.frequencies_hz < 3000)
    exact = accelerance(SINGLE, frf.frequencies_hz[band])
    assert np.abs(frf.h1[:, band] - exact).max() / np.abs(exact).max() < 2e-4
    windowed = estimate_frf(blow_spectra(clean.force_n, clean.accel_m_per_s2, clean.fs_hz), [0, 1, 2])
    assert np.allclose(windowed.h1, estimate_frf(spectra_of(clean, WindowConfig()), [0, 1, 2]).h1)
    one = estimate_frf(blow_spectra(clean.force_n[1], clean.accel_m_per_s2[1], clean.fs_hz), [0])
    assert one.h1.shape == windowed.h1.shape and one.used == (0,)
    with pytest.raises(InputError, match="expected"):
        blow_spectra(clean.force_n, clean.accel_m_per_s2[:2], clean.fs_hz)


def test_the_analysed_span_follows_the_ring_down():
    """Lighter damping rings longer and gets a longer span; noise alone, or with a steady tone (mains hum), gets
    the least span; a record too short to tell is kept whole."""
    fs, n = 20480.0, 65536
    t = np.arange(n) / fs
    rng = np.random.default_rng(3)
    noise = rng.normal(0.0, 1e-3, (2, 3, n))
    spans = []
    for zeta in (0.02, 0.005, 0.002):
        ring = np.exp(-zeta * 2 * np.pi * 600.0 * t) * np.sin(2 * np.pi * 600.0 * t)
        spans.append(ring_down_samples(noise + ring))
        # where the ring has sunk into the noise: its amplitude a few times the noise's σ at most
        assert np.exp(-zeta * 2 * np.pi * 600.0 * spans[-1] / fs) < 0.01
        assert np.exp(-zeta * 2 * np.pi * 600.0 * max(spans[-1] - 1024, 0) / fs) > 1e-4
    assert spans[0] < spans[1] < spans[2]
    assert analysed_samples(noise, fs) == pytest.approx(MIN_SPAN_S * fs, rel=0.05)
    hum = 0.01 * np.sin(2 * np.pi * 50.0 * t)
    assert analysed_samples(noise + hum, fs) == analysed_samples(noise, fs)
    assert analysed_samples(noise[..., :4096], fs) == 4096
    slow = noise + 0.1 * np.sin(2 * np.pi * 5.0 * t) * np.exp(-0.5 * t)  # a support mode 100 σ strong: no ring-down
    assert ring_down_samples(slow) < 0.05 * n


def test_trimmed_spectra_keep_the_blow_and_the_windows_rate():
    s = synth_impacts(SINGLE, CHANNELS, n_samples=32768, snr_db=60.0, seed=4)
    sp = spectra_of(s, WindowConfig())
    whole = spectra_of(s, WindowConfig(trim_to_decay=False))
    assert sp.n_samples < whole.n_samples == s.force_n.shape[1]
    assert sp.decay_rate_per_s == whole.decay_rate_per_s  # the window's rate is the record's, trimmed or not
    h_trim = estimate_frf(sp, [0, 1, 2]).h1[0]
    h_whole = np.interp(sp.frequencies_hz, whole.frequencies_hz, estimate_frf(whole, [0, 1, 2]).h1[0].real)
    near = np.abs(sp.frequencies_hz - F0) < 50
    assert np.allclose(h_trim.real[near], h_whole[near], rtol=1e-3, atol=1e-3 * np.abs(h_whole[near]).max())
