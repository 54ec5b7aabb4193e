"""The load-step pipeline against synthetic impact sets with known truth."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from labctl.errors import InputError
from labctl.physics import TrippContact, material, roller, roller_stiffness_from_bounce
from labctl.physics.rig_config import Disc
from labctl.processing import CheckConfig, IdentifyConfig, ProcessingError, identify
from tests.synth_impacts import load_rig, paper_case_modes, rig_set, synth_impacts

RIG = load_rig()
N = 32768  # 1.6 s records keep the tests quick; every response has died out long before


def run(s, rig=RIG, **kw):
    return identify(s.force_n, s.accel_m_per_s2, s.fs_hz, s.channels, rig, **kw)


@pytest.fixture(scope="module")
def paper_case():
    s = synth_impacts(paper_case_modes(), RIG.channels, n_samples=N, snr_db=40.0, seed=11,
                      pulse_s=[2.5e-4, 3.5e-4, 4.5e-4], peak_force_n=[150.0, 300.0, 450.0])
    return s, run(s)


def test_paper_case_bounce_tilt_pair_damping_and_stiffness(paper_case):
    s, r = paper_case
    assert r.accepted == [0, 1, 2]
    assert r.bounce_hz == pytest.approx(745.0, abs=max(4 * r.bounce_hz_std, 0.003))
    assert 0 < r.bounce_hz_std < 0.003
    assert r.tilt_pair_resolved
    assert r.tilt_hz[0] == pytest.approx(580.0, abs=0.3) and r.tilt_hz[1] == pytest.approx(582.0, abs=0.3)
    assert r.bounce_damping_ratio == pytest.approx(0.018, rel=0.002)  # the window's damping removed
    # a 2 Hz tilt split: slightly unequal rollers, whose mean sits within 1e-4 of the equal-roller value
    assert r.roller_stiffness_n_per_m == pytest.approx(roller_stiffness_from_bounce(RIG, 745.0), rel=1e-4)
    assert r.roller_stiffnesses_resolved and len(r.roller_stiffnesses_n_per_m) == 3
    assert np.mean(r.roller_stiffnesses_n_per_m) == pytest.approx(r.roller_stiffness_n_per_m, rel=1e-12)
    budget = r.roller_stiffness_budget_n_per_m
    assert set(budget) == {"modal_fit", "disc_mass", "setup_stiffness", "rig_model"}
    k_hi = roller_stiffness_from_bounce(RIG, r.bounce_hz + r.bounce_hz_std)
    # the bounce's σ, widened a little because the split may be the discs' inertia asymmetry, not the rollers'
    # (unequal rollers move the bounce at second order)
    assert 0 < budget["modal_fit"] < 4 * (k_hi - r.roller_stiffness_n_per_m)
    # the rig file's uncertainties (1 % mass, 10 % K_setup, 0.3 % model) dominate: about 1.5 % in all
    assert r.roller_stiffness_std_n_per_m == pytest.approx(np.sqrt(sum(v**2 for v in budget.values())), rel=1e-9)
    assert 0.01 < r.roller_stiffness_std_n_per_m / r.roller_stiffness_n_per_m < 0.02
    assert r.coherence_at_bounce > 0.99
    kinds = [m.kind for m in r.modes]
    assert kinds == ["bounce", "tilt", "tilt"]
    bounce = r.modes[0]
    assert bounce.bounce_mac > 0.95
    top = [bounce.shape[c] for c in ("A1Z", "A2Z", "A3Z")]
    assert np.all(np.sign(top) == np.sign(top[0])) and np.sign(bounce.shape["A4Z"]) == -np.sign(top[0])
    tilt = r.modes[1]
    assert abs(sum(tilt.shape[c] for c in ("A1Z", "A2Z", "A3Z"))) < 0.1 and abs(tilt.shape["A4Z"]) < 0.05


def test_the_result_holds_the_frf_and_a_json_ready_summary(paper_case):
    _, r = paper_case
    assert r.h1.shape == r.h2.shape == r.coherence.shape == (12, len(r.frequencies_hz))
    assert r.frequencies_hz[-1] <= 5000.0
    d = json.loads(json.dumps(r.to_dict()))
    for key in ("bounce_hz", "bounce_damping_ratio", "tilt_hz", "roller_stiffness_n_per_m", "coherence_at_bounce",
                "impacts"):
        assert key in d
    assert d["impacts"][0] == {**d["impacts"][0], "index": 0, "accepted": True, "reasons": []}
    assert len(d["tilt_hz"]) == 2 and "h1" not in d


def test_rejected_impacts_stay_with_their_reason_and_the_rest_is_used():
    s = synth_impacts(paper_case_modes(), RIG.channels, n_samples=N, snr_db=40.0, seed=12, n_impacts=4,
                      double_hits={1: (5e-3, 0.3)}, pulse_s=[3e-4, 3e-4, 1.6e-3, 3e-4])
    r = run(s)
    assert [c.reasons for c in r.impacts] == [(), ("double_hit",), ("pulse_width",), ()]
    assert r.accepted == [0, 3]
    assert r.bounce_hz == pytest.approx(745.0, abs=0.005)


def test_an_impact_that_spoils_the_coherence_at_the_bounce_is_rejected():
    s = synth_impacts(paper_case_modes(), RIG.channels, n_samples=N, snr_db=40.0, seed=13, n_impacts=4)
    t = np.arange(N) / s.fs_hz
    rattle = np.sin(2 * np.pi * 744.0 * t + 1.0) * np.exp(-t / 0.3)  # something else rings at the bounce
    s.accel_m_per_s2[2] += rattle[None, :]
    r = run(s)
    assert r.impacts[2].reasons == ("low_coherence",)
    assert r.accepted == [0, 1, 3]
    assert r.coherence_at_bounce > 0.99
    assert r.bounce_hz == pytest.approx(745.0, abs=0.005)
    kept = run(s, config=CheckConfig(min_coherence=0.0))
    assert kept.accepted == [0, 1, 2, 3]
    assert kept.coherence_at_bounce < 0.9 and abs(kept.bounce_hz - 745.0) > 0.1  # what the check protects from


def test_a_dead_sensor_is_left_out_and_the_modes_still_come_out():
    s = synth_impacts(paper_case_modes(), RIG.channels, n_samples=N, snr_db=40.0, seed=14, dead=["A1Z"])
    r = run(s)
    assert r.dead_channels == ("A1Z",)
    assert r.accepted == [0, 1, 2]
    assert r.classified_by_shape
    assert r.bounce_hz == pytest.approx(745.0, abs=0.005)
    assert r.tilt_hz[0] == pytest.approx(580.0, abs=0.4) and r.tilt_hz[1] == pytest.approx(582.0, abs=0.4)
    assert any("A1Z" in w for w in r.warnings)


def test_equal_rollers_give_a_degenerate_tilt_pair_reported_as_such():
    s = rig_set(4.65e7, n_samples=N, snr_db=40.0, seed=15)
    r = run(s)
    assert not r.tilt_pair_resolved
    assert r.tilt_hz[0] == r.tilt_hz[1] == pytest.approx(s.truth["tilt_hz"][0], abs=0.01)
    assert r.bounce_hz == pytest.approx(s.truth["bounce_hz"], abs=0.005)
    assert r.roller_stiffness_n_per_m == pytest.approx(4.65e7, rel=1e-4)


@pytest.mark.parametrize("ks", [[1.0, 1.0, 1.05], [1.0, 1.1, 0.9], [1.0, 1.0, 1.3]])
def test_bounce_found_when_a_tilt_mode_comes_close_on_uneven_rollers(ks):
    disc = Disc(11.6, 0.036, 0.022)  # a lighter-inertia rig: tilt within a few % of the bounce
    rig = dataclasses.replace(RIG, upper=disc, lower=disc)
    s = rig_set(np.array(ks) * 4.65e7, rig=rig, n_samples=N, snr_db=40.0, seed=16)
    r = run(s, rig=rig)
    gap = min(abs(s.truth["bounce_hz"] - t) for t in s.truth["tilt_hz"])
    assert gap < 40.0  # a bandwidth and a half
    assert r.bounce_hz == pytest.approx(s.truth["bounce_hz"], abs=0.01)
    assert r.modes[0].bounce_mac > max(m.bounce_mac for m in r.modes[1:])


def test_roller_only_stiffness_removes_the_rails_tripp_compliance(paper_case):
    s, r = paper_case
    contact = TrippContact(roller(1), material("1.3505"), 3e-3)
    alone = run(s, contact=contact, load_n=440.0)
    expected = 1.0 / (1.0 / r.roller_stiffness_n_per_m - float(contact.rail_compliance_m_per_n(440.0)))
    assert alone.roller_only_stiffness_n_per_m == pytest.approx(expected, rel=1e-9)
    assert alone.roller_only_stiffness_n_per_m > 1.5 * r.roller_stiffness_n_per_m
    assert alone.roller_only_stiffness_std_n_per_m > r.roller_stiffness_std_n_per_m
    assert "roller_only_stiffness_n_per_m" in alone.to_dict()


def test_nothing_usable_raises_a_processing_error_naming_the_reasons():
    s = synth_impacts(paper_case_modes(), RIG.channels, n_samples=N, snr_db=40.0, seed=17, n_impacts=2,
                      double_hits={0: (1e-3, 0.5), 1: (20e-3, 0.1)})
    with pytest.raises(ProcessingError, match=r"all 2 impacts rejected.*impact 0: double_hit.*impact 1: double_hit"):
        run(s)
    flat = synth_impacts(paper_case_modes(), RIG.channels, n_samples=N, snr_db=40.0, seed=18,
                         dead=list(RIG.channels))
    with pytest.raises(ProcessingError, match="flat"):
        run(flat)


def test_bad_inputs_are_named():
    s = synth_impacts(paper_case_modes(), RIG.channels, n_samples=4096, seed=19, n_impacts=1)
    with pytest.raises(InputError, match="B1Z"):
        identify(s.force_n, s.accel_m_per_s2, s.fs_hz, ("B1Z", *RIG.channels[1:]), RIG)
    with pytest.raises(InputError, match="shape"):
        identify(s.force_n, s.accel_m_per_s2[:, :, :-1], s.fs_hz, RIG.channels, RIG)
    bad = s.accel_m_per_s2.copy()
    bad[0, 3, 100] = np.nan
    with pytest.raises(InputError, match="non-finite"):
        identify(s.force_n, bad, s.fs_hz, RIG.channels, RIG)
    with pytest.raises(InputError, match="sample rate"):
        identify(s.force_n, s.accel_m_per_s2, -1.0, RIG.channels, RIG)


def test_no_exponential_window_gives_the_same_modes(paper_case):
    s, r = paper_case
    from labctl.processing import WindowConfig

    plain = run(s, config=IdentifyConfig(window=WindowConfig(exponential_end=None)))
    assert plain.window_decay_rate_per_s == 0.0 and r.window_decay_rate_per_s > 0
    assert plain.bounce_hz == pytest.approx(r.bounce_hz, abs=3 * r.bounce_hz_std)
    assert plain.bounce_damping_ratio == pytest.approx(r.bounce_damping_ratio, rel=1e-3)


def test_fitting_every_third_line_keeps_the_answer_and_its_sigma(monkeypatch):
    """The window correlates neighbouring lines, so a fit on every ``fit_line_step``-th line (its noise
    inflation divided by the step) gives the every-line answer within a fraction of σ and the same σ."""
    from labctl.processing import WindowConfig
    from labctl.processing.frf import Spectra

    sets = [synth_impacts(paper_case_modes(), RIG.channels, n_samples=N, snr_db=40.0, seed=300 + i,
                          force_peak_snr_db=50.0) for i in range(4)]
    whole = IdentifyConfig(window=WindowConfig(trim_to_decay=False))  # the window's correlation spans the record
    thinned = [run(s, config=whole) for s in sets]
    assert all(r.frequencies_hz[1] * N == pytest.approx(r.fs_hz) for r in thinned)
    monkeypatch.setattr(Spectra, "fit_line_step", property(lambda self: 1))
    every = [run(s, config=whole) for s in sets]
    for a, b in zip(thinned, every, strict=True):
        assert abs(a.bounce_hz - b.bounce_hz) < 0.2 * b.bounce_hz_std
        assert a.bounce_hz_std == pytest.approx(b.bounce_hz_std, rel=0.05)


def test_the_spectra_span_the_ring_down_and_keep_the_whole_records_answer():
    """Past the ring-down a record holds noise only: the spectra of the span up to twice the ring-down give the
    whole record's answer within a fraction of its σ, with no larger σ, on a fraction of the lines."""
    from labctl.processing import WindowConfig

    whole = IdentifyConfig(window=WindowConfig(trim_to_decay=False))
    for i in range(3):
        s = synth_impacts(paper_case_modes(), RIG.channels, n_samples=N, snr_db=40.0, seed=310 + i,
                          force_peak_snr_db=50.0)
        trimmed, full = run(s), run(s, config=whole)
        assert trimmed.frequencies_hz[1] >= 4 * full.frequencies_hz[1]  # a quarter of the record or less
        assert abs(trimmed.bounce_hz - full.bounce_hz) < 0.5 * full.bounce_hz_std
        assert trimmed.bounce_hz_std < 1.1 * full.bounce_hz_std
        assert abs(trimmed.bounce_hz - 745.0) < 3 * trimmed.bounce_hz_std


def test_a_pole_far_less_damped_than_the_rigs_modes_is_residue_not_a_tilt():
    """One channel at 40 dB: a three-mode fit can put a needle-sharp pole (ζ ≈ 0.003 against the rig's 0.018)
    on the noise beside the bounce. Contact modes damp alike, so such a pole is residue: the pair stays
    unresolved and the bounce is the true one, not the needle."""
    import math

    rig = load_rig()
    decay_s = math.log(100.0) / (0.018 * 2 * math.pi * 580.0)
    s = synth_impacts(paper_case_modes(745.0, (580.0, 582.0), 0.018, rig=rig, channels=("A1Z",)), ("A1Z",),
                      snr_db=40.0, seed=600039, snr_decay_s=decay_s, force_peak_snr_db=50.0)
    r = run(s, rig, accel_ranges=50 * 9.80665, force_range_n=2224.0)
    assert min(m.damping_ratio for m in r.modes) > 0.018 / 5
    assert not (r.tilt_pair_resolved and max(r.tilt_hz) > 700.0)
    assert abs(r.bounce_hz - 745.0) < 3 * r.bounce_hz_std
