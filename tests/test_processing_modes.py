"""The multi-channel mode fit and the bounce/tilt classification against exact modal models."""

from __future__ import annotations

import numpy as np
import pytest

from labctl.processing.modes import fit_modes, lscf_poles, pole_to_mode
from labctl.processing.shapes import classify, predicted_shapes, separation
from tests.synth_impacts import accelerance, load_rig, paper_case_modes

RIG = load_rig()
CONTACT = {"bounce", "tilt"}


def band_frf(modes, lo=480.0, hi=860.0, df=0.3125, noise=0.0, seed=0):
    f = np.arange(lo, hi, df)
    h = accelerance(modes, f)
    if noise:
        rng = np.random.default_rng(seed)
        h = h + noise * (rng.standard_normal(h.shape) + 1j * rng.standard_normal(h.shape))
    return f, h


def test_fit_recovers_an_exact_three_mode_model_with_out_of_band_modes():
    modes = paper_case_modes()  # support modes below, flexible modes above the band
    f, h = band_frf(modes)
    fit = fit_modes(f, h, [(575.0, 0.02), (585.0, 0.02), (750.0, 0.02)])
    assert fit.converged
    assert fit.frequencies_hz == pytest.approx([580.0, 582.0, 745.0], abs=2e-3)
    assert fit.damping_ratios == pytest.approx([0.018] * 3, rel=1e-3)
    truth = np.array([m.residue for m in modes if m.kind in CONTACT])
    assert np.abs(fit.constants - truth).max() < 2e-3 * np.abs(truth).max()


def test_uncertainties_match_the_scatter_over_noise_draws():
    modes = paper_case_modes()
    estimates, stds = [], []
    for seed in range(12):
        f, h = band_frf(modes, noise=2e-3, seed=seed)
        fit = fit_modes(f, h, [(580.0, 0.018), (582.0, 0.018), (745.0, 0.018)])
        estimates.append(fit.frequencies_hz[2])
        stds.append(fit.frequency_std_hz[2])
    scatter = float(np.std(estimates, ddof=1))
    assert 0.5 < scatter / float(np.mean(stds)) < 1.8
    assert abs(float(np.mean(estimates)) - 745.0) < 3 * float(np.mean(stds))


def test_lscf_start_poles_land_near_the_modes():
    f, h = band_frf(paper_case_modes(), noise=1e-4)
    found = sorted(pole_to_mode(p) for p in lscf_poles(f, h, 3) if p.imag > 0)
    assert [fr for fr, _ in found] == pytest.approx([580.0, 582.0, 745.0], abs=0.5)
    assert [z for _, z in found] == pytest.approx([0.018] * 3, rel=0.1)


def test_a_mode_the_data_do_not_hold_has_no_significance():
    modes = [m for m in paper_case_modes() if m.kind != "tilt" or m.frequency_hz < 581]
    f, h = band_frf(modes, noise=1e-3)
    fit = fit_modes(f, h, [(580.0, 0.018), (745.0, 0.018), (800.0, 0.02)])
    assert fit.significance[0] > 1e4 and fit.significance[1] > 1e4
    assert fit.significance[2] < 100


def test_classification_by_shape_with_all_and_with_dead_channels():
    modes = [m for m in paper_case_modes() if m.kind in CONTACT]
    constants = np.array([m.residue for m in modes])  # tilt, tilt, bounce
    freqs = np.array([m.frequency_hz for m in modes])
    pred = predicted_shapes(RIG, RIG.channels)
    for dead in ([], ["A1Z"], ["A4Z"], ["A1Z", "A2X"], ["A3Z", "A1X", "A1Y"]):
        live = np.array([c not in dead for c in RIG.channels])
        cls = classify(constants, freqs, pred, live)
        assert cls.by_shape
        assert cls.bounce == 2 and cls.tilt == (0, 1)
        assert cls.bounce_mac[2] > 0.95 and cls.tilt_fraction[:2].min() > 0.95
    # with A1Z and A4Z both dead the two remaining vertical sensors cannot tell bounce from tilt
    live = np.array([c not in ("A1Z", "A4Z") for c in RIG.channels])
    cls = classify(constants, freqs, pred, live)
    assert not cls.by_shape and cls.bounce == 2


def test_classification_falls_back_to_frequency_order_when_shapes_cannot_tell():
    pred = predicted_shapes(RIG, ["A1Z"])
    live = np.array([True])
    assert separation(pred, live) < 0.2
    cls = classify(np.array([[0.01], [0.02], [0.04]]), np.array([580.0, 582.0, 745.0]), pred, live)
    assert not cls.by_shape and cls.bounce == 2


def test_the_noise_scaled_stopping_rule_lands_within_a_small_share_of_sigma_of_the_minimum(monkeypatch):
    """Stopping once the Gauss–Newton step promises < GN_TOLERANCE noise variances costs no accuracy."""
    import labctl.processing.modes as modes_mod

    f, h = band_frf(paper_case_modes(), noise=2e-3, seed=4)
    start = [(579.0, 0.02), (583.5, 0.016), (748.0, 0.02)]
    quick = fit_modes(f, h, start)
    monkeypatch.setattr(modes_mod, "GN_TOLERANCE", 1e-12)
    tight = fit_modes(f, h, start, max_iter=200)
    assert quick.converged and tight.converged
    assert np.all(np.abs(quick.frequencies_hz - tight.frequencies_hz) < 0.05 * tight.frequency_std_hz)
    assert quick.cost - tight.cost < 0.01 * tight.sigma2
