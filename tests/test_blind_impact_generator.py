"""The blind impact generator (``bench/blind/impact_generator.py``): its files meet the impacts NPZ contract, its
eigen-model reproduces Eq. 4 and the paper's 748/584 Hz, and the sampled signals carry those modes."""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from labctl.physics.rig_config import load_rig

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench" / "blind"))
import impact_generator as gen  # noqa: E402
from blind_rig import build_model, eq4_bounce_hz, eq4_stiffness, paper_rig  # noqa: E402

RIG = paper_rig()
K_440N = eq4_stiffness(748.0, RIG)  # type 1 at 440 N: the stiffness Eq. 4 gives for the measured bounce


@pytest.fixture(scope="module")
def clean():
    return gen.generate(gen.PRESETS["clean_440n"], 7, RIG)


@pytest.fixture(scope="module")
def noisy():
    return gen.generate(gen.PRESETS["unequal_transverse"], 3, RIG)


def _spectra(arrays: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    f = np.fft.rfftfreq(arrays["force"].shape[-1], 1 / float(arrays["fs"]))
    return f, np.fft.rfft(arrays["force"], axis=-1), np.fft.rfft(arrays["accel"], axis=-1)


@pytest.mark.parametrize("which", ["clean", "noisy"])
def test_arrays_meet_the_impacts_npz_contract(which, request, tmp_path):
    arrays, truth = request.getfixturevalue(which)
    assert np.ndim(arrays["fs"]) == 0 and float(arrays["fs"]) == 20480.0
    assert arrays["force"].shape == (3, 65536)
    assert arrays["accel"].shape == (3, 12, 65536)
    assert list(arrays["channels"]) == [f"A{s}{a}" for s in range(1, 5) for a in "XYZ"]
    assert np.all(np.isfinite(arrays["force"])) and np.all(np.isfinite(arrays["accel"]))
    np.savez(tmp_path / "x.npz", **arrays)
    with np.load(tmp_path / "x.npz", allow_pickle=False) as back:  # plain arrays, no pickled objects
        assert back["accel"].shape == arrays["accel"].shape and back["channels"].dtype.kind == "U"
    pre = truth["case"]["pretrigger_samples"]
    peak = arrays["force"].argmax(axis=1)
    assert np.all((peak > pre) & (peak < pre + 0.5e-3 * 20480 + 2))  # a short pretrigger, the blow just after it
    assert np.all(arrays["force"].max(axis=1) > 0.85 * truth["case"]["peak_force_n"][0])


def _short(name: str):
    """A preset cut to one short impact: the truth does not depend on the record's length."""
    return replace(gen.PRESETS[name], impacts=1, samples=8192)


def test_the_same_seed_gives_the_same_file_and_another_seed_another():
    first, again, other = (gen.generate(_short("equal"), seed, RIG)[0] for seed in (7, 7, 8))
    np.testing.assert_array_equal(again["accel"], first["accel"])
    assert not np.allclose(other["accel"], first["accel"])


def test_equal_symmetric_rig_at_440n_bounces_at_748_and_tilts_at_584_hz():
    model = build_model(RIG, np.full(3, K_440N))
    assert 4.4e7 < K_440N < 4.9e7  # Eq. 5 for type 1 at 440 N on Ra 0.2 µm rails gives 4.5e7 N/m
    assert model.freqs_hz[model.bounce] == pytest.approx(748.0, abs=5.0)
    tilts = model.freqs_hz[list(model.tilts)]
    assert tilts == pytest.approx([584.0, 584.0], abs=5.0)
    assert abs(tilts[1] - tilts[0]) < 1e-6  # a degenerate pair


@pytest.mark.parametrize("k", [2e7, K_440N, 6.6e8])
def test_the_eigen_model_without_support_is_eq4_and_its_tilt_analogue(k):
    free = replace(RIG, support_stiffness_n_per_m=0.0)
    model = build_model(free, np.full(3, k))
    assert model.freqs_hz[model.bounce] == pytest.approx(eq4_bounce_hz(k, RIG), rel=1e-9)
    k_total = 1 / (1 / (3 * k) + 1 / RIG.setup_stiffness_n_per_m)  # relative tilt: ω² = K_total·r²/I
    tilt = np.sqrt(k_total * RIG.contact_radius_m**2 / RIG.upper_inertia_kg_m2) / (2 * np.pi)
    assert model.freqs_hz[list(model.tilts)] == pytest.approx([tilt, tilt], rel=1e-9)
    # the support adds its own three low modes and barely moves the contact modes
    supported = build_model(RIG, np.full(3, k))
    assert max(supported.freqs_hz[r] for r in range(6) if r not in supported.contact_modes) < 60.0
    assert supported.freqs_hz[supported.bounce] == pytest.approx(eq4_bounce_hz(k, RIG), rel=2e-3)


def test_a_generated_z_spectrum_peaks_at_the_bounce_and_the_tilt(clean):
    arrays, truth = clean
    f, _, acc = _spectra(arrays)
    z = acc[:, [2, 5, 8], :]
    band = (f > 400) & (f < 1000)
    in_phase = np.abs(z.sum(axis=1)).mean(axis=0)  # the three upper Z together: the bounce
    across = np.abs(z[:, 0] - (z[:, 1] + z[:, 2]) / 2).mean(axis=0)  # A1 against A2, A3: a tilt
    assert f[band][in_phase[band].argmax()] == pytest.approx(truth["bounce_hz"], abs=1.5)
    assert f[band][across[band].argmax()] == pytest.approx(truth["tilt_mean_hz"], abs=1.5)
    assert truth["bounce_hz"] == pytest.approx(748.0, abs=5) and truth["tilt_mean_hz"] == pytest.approx(584.0, abs=5)


def test_the_sampled_frf_is_the_models_accelerance():
    """The DAQ filter is common to force and acceleration: without noise, H1 below 0.45·fs is the model's."""
    quiet = replace(gen.PRESETS["clean_440n"], snr_db=(250.0, 250.0), force_snr_db=(250.0, 250.0))
    arrays, truth = gen.generate(quiet, 7, RIG)
    f, force, acc = _spectra(arrays)
    h1 = (acc * force.conj()[:, None, :]).sum(axis=0) / (np.abs(force) ** 2).sum(axis=0)
    model = build_model(RIG, np.asarray(truth["k_n_per_m"]))
    w, wr = 2 * np.pi * f, 2 * np.pi * model.freqs_hz
    damping = np.full(6, RIG.support_damping_ratio)
    damping[list(model.contact_modes)] = truth["damping_ratio"]
    frames, _ = gen.draw_frames(RIG, gen.PRESETS["clean_440n"], np.random.default_rng(0))  # no sensor errors
    b = truth["blows"]
    q = -np.array([1.0, np.mean([x["y_m"] for x in b]), -np.mean([x["x_m"] for x in b]), 0, 0, 0])
    weights = (gen.sensor_matrix(RIG, gen.PRESETS["clean_440n"], frames) @ model.shapes) * (model.shapes.T @ q)
    for f0 in (truth["bounce_hz"], truth["tilt_mean_hz"], 30.0, 300.0, 1500.0, 8000.0):
        i = np.argmin(np.abs(f - f0))
        expected = weights @ (-(w[i] ** 2) / (wr**2 - w[i] ** 2 + 2j * damping * wr * w[i]))
        np.testing.assert_allclose(h1[:, i], expected, rtol=1e-6, atol=1e-9 * np.abs(expected).max())


def test_noise_is_set_by_the_snr_over_the_decay(noisy):
    arrays, truth = noisy
    pre = truth["case"]["pretrigger_samples"]
    for n, blow in enumerate(truth["blows"]):
        floor = arrays["accel"][n, :, : pre - 10].std()
        assert floor == pytest.approx(blow["accel_noise_std"], rel=0.05)
        z_snr = [blow["channel_snr_db"][c] for c in ("A1Z", "A2Z", "A3Z", "A4Z")]
        assert np.median(z_snr) == pytest.approx(truth["snr_db"], abs=0.01)
        assert arrays["force"][n, : pre - 10].std() == pytest.approx(blow["force_noise_std"], rel=0.1)
    assert 30 <= truth["snr_db"] <= 50 and 40 <= truth["force_snr_db"] <= 60


def test_truth_names_the_unequal_rollers_and_the_inertia_split():
    _, unequal = gen.generate(_short("unequal_15"), 5, RIG)
    k = np.asarray(unequal["k_n_per_m"])
    assert sorted(k / k.mean()) == pytest.approx([0.85, 1.0, 1.15])
    assert unequal["rollers_differing_5pct"] == [i + 1 for i in range(3) if abs(k[i] / k.mean() - 1) > 0.1]
    _, large = gen.generate(_short("asym_large"), 5, RIG)
    _, small = gen.generate(_short("asym_small"), 5, RIG)
    assert 6.0 < large["tilt_split_hz"] < 10.0 and 0.7 < small["tilt_split_hz"] < 3.5
    assert large["rollers_differing_5pct"] == [] and large["bounce_hz"] == pytest.approx(748.0, abs=2.0)
    ia = large["inertia_asymmetry"]
    assert (ia["ixx_kg_m2"] + ia["iyy_kg_m2"]) / 2 == pytest.approx(RIG.upper_inertia_kg_m2)


def test_the_matched_rig_reads_as_a_labctl_rig_with_the_generators_numbers(tmp_path):
    cfg = load_rig(gen.write_rig(tmp_path / "rig.toml", gen.PRESETS["asym_large"], RIG))
    assert cfg.upper.mass_kg == RIG.upper_mass_kg and cfg.lower.mass_kg == RIG.lower_mass_kg
    assert cfg.upper.inertia_kg_m2 == pytest.approx(RIG.upper_inertia_kg_m2)
    assert cfg.setup_stiffness_n_per_m == RIG.setup_stiffness_n_per_m
    assert cfg.contact_radius_m == pytest.approx(RIG.contact_radius_m)
    assert [s.name for s in cfg.sensors] == ["A1", "A2", "A3", "A4"]


def test_cli_writes_npz_truth_and_rig_and_refuses_an_unknown_preset(tmp_path, capsys):
    assert gen.main(["--out", str(tmp_path), "--preset", "equal", "--seeds", "1", "--first-seed", "4"]) == 0
    truth = json.loads((tmp_path / "equal_s4.json").read_text())
    assert truth["seed"] == 4 and (tmp_path / truth["rig_file"]).is_file()
    assert (tmp_path / "equal_s4.npz").is_file()
    assert gen.main(["--out", str(tmp_path), "--preset", "nope"]) == 2
    assert "expected one of" in capsys.readouterr().err
