"""The twin's vectorised synthesis against the physics written out term by term (one mode, one channel, one
sample at a time): the pulse, the modal superposition and the ADC."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.sim.response import Blow, ModalModel, accelerance, digitise, response

FS_HZ = 20_480.0


@pytest.fixture(scope="module")
def model() -> ModalModel:
    rng = np.random.default_rng(7)
    freqs = np.array([60.0, 95.0, 584.0, 590.0, 748.0, 2310.0])
    return ModalModel(freqs, np.full(freqs.size, 0.02), rng.normal(0.0, 0.2, (freqs.size, 4)),
                      ("A1X", "A1Z", "A2Z", "A3Z"))


def test_half_sine_pulse_matches_its_formula_sample_by_sample() -> None:
    blow = Blow(peak_n=250.0, width_s=0.3e-3, x_m=0.0, y_m=0.0, second_delay_s=1.5e-3, second_ratio=0.4)
    t = np.arange(512) / FS_HZ
    onset = 100.3 / FS_HZ
    got = blow.force_n(t, onset)

    def one(tau: float, peak: float) -> float:
        return peak * math.sin(math.pi * tau / blow.width_s) if 0.0 <= tau <= blow.width_s else 0.0

    want = [one(x - onset, 250.0) + one(x - onset - 1.5e-3, 100.0) for x in t]
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9)
    assert np.count_nonzero(got) == sum(w != 0.0 for w in want) > 0
    # the pulse's area is its impulse (both pulses), to the sampling's resolution
    assert got.sum() / FS_HZ == pytest.approx(blow.impulse_n_s(), rel=0.02)
    # an unsorted time axis gives the same samples
    order = np.random.default_rng(1).permutation(t.size)
    np.testing.assert_array_equal(blow.force_n(t[order], onset), got[order])


def test_accelerance_is_the_sum_of_modal_terms(model: ModalModel) -> None:
    f = np.linspace(0.0, 3000.0, 301)
    got = accelerance(model, f)
    want = np.zeros((len(model.channels), f.size), dtype=complex)
    for r, (fr, z) in enumerate(zip(model.frequencies_hz, model.damping_ratios, strict=True)):
        for c in range(len(model.channels)):
            for k, fk in enumerate(f):
                w, wr = 2 * math.pi * fk, 2 * math.pi * fr
                want[c, k] += model.participation[r, c] * -(w**2) / (wr**2 - w**2 + 2j * z * wr * w)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)


def test_response_is_the_force_spectrum_times_the_accelerance(model: ModalModel) -> None:
    n = 4096
    force = Blow(200.0, 0.3e-3, 0.0, 0.0).force_n(np.arange(n) / FS_HZ, 64 / FS_HZ)
    got = response(model, force, FS_HZ)
    h = accelerance(model, np.fft.rfftfreq(n, 1 / FS_HZ))
    want = np.array([np.fft.irfft(h[c] * np.fft.rfft(force), n) for c in range(len(model.channels))])
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12 * np.abs(want).max())
    # a second record of another length and rate gets its own frequency grid
    other = response(model, force[: n // 2], FS_HZ / 2)
    assert other.shape == (4, n // 2) and not np.allclose(other, got[:, : n // 2])


def test_digitise_quantises_clips_and_flags_each_row() -> None:
    signal = np.array([[0.1, -0.2, 0.3], [0.5, 1.7, -0.1], [-2.0, 0.0, 0.0]])
    out, clipped = digitise(signal, 1.0, 4)  # 16 levels over ±1: a step of 0.125
    np.testing.assert_allclose(out, [[0.125, -0.25, 0.25], [0.5, 1.0, -0.125], [-1.0, 0.0, 0.0]])
    assert clipped.tolist() == [False, True, True]
    one, flag = digitise(np.array([0.3, -0.9]), 1.0, 4)
    assert flag.shape == (1,) and not flag[0] and one.tolist() == [0.25, -0.875]
    np.testing.assert_array_equal(signal[1], [0.5, 1.7, -0.1])  # the input is not modified
