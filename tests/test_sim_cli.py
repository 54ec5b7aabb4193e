"""``labctl simulate impacts``: the issue's acceptance, checked with an H1 estimate written here (not labctl's)."""

from __future__ import annotations

import numpy as np
import pytest

from labctl.physics import load_rig, rig_modes
from tests.cli_util import assert_one_line_error, labctl, labctl_json
from tests.test_sim_support import bounce_and_tilt_peaks, h1, peak_hz, pulse_width_s

RIG = load_rig()


@pytest.fixture(scope="module")
def acceptance(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "x.npz"
    truth = labctl_json("simulate", "impacts", "--roller-type", "1", "--load-n", "440", "--out", str(out))
    with np.load(out, allow_pickle=False) as npz:
        data = {k: npz[k] for k in npz.files}
    return truth, data


def test_npz_layout(acceptance):
    _, d = acceptance
    assert float(d["fs"]) == 20_480
    assert d["force"].shape == (3, 65_536) and d["accel"].shape == (3, 12, 65_536)
    assert d["channels"].dtype.kind == "U"
    assert d["channels"].tolist() == [f"A{i}{ax}" for i in range(1, 5) for ax in "XYZ"]


def test_truth_is_consistent_with_the_rig_model(acceptance):
    truth, _ = acceptance
    assert truth["load_n"] == 440
    ks = truth["roller_stiffness_n_per_m"]
    assert len(ks) == 3
    modes = rig_modes(RIG, ks)
    assert truth["bounce_hz"] == pytest.approx(modes.bounce_hz, rel=1e-9)
    assert truth["tilt_hz"] == pytest.approx(list(modes.tilt_hz), rel=1e-9)
    assert truth["bounce_hz"] == pytest.approx(745, rel=0.02)  # default world, type 1, 440 N (paper Fig. 6)


def test_independent_h1_finds_bounce_and_tilt(acceptance):
    truth, d = acceptance
    freqs, frf = h1(d["force"], d["accel"], float(d["fs"]))
    bounce, tilt = bounce_and_tilt_peaks(freqs, frf, d["channels"].tolist())
    assert bounce == pytest.approx(truth["bounce_hz"], rel=0.005)
    assert tilt == pytest.approx(0.78 * bounce, rel=0.03)
    # the tilt pair (split by unequal rollers, far closer than its half-power bandwidth) shows as one peak
    assert 0.99 * truth["tilt_hz"][0] < tilt < 1.01 * truth["tilt_hz"][1]
    # the rig file's first flexible disc mode shows above 2 kHz
    a1z = frf[d["channels"].tolist().index("A1Z")]
    flex_hz = RIG.flexible_modes[0].frequency_hz
    assert flex_hz > 2000 and peak_hz(freqs, a1z, 1500, 3000) == pytest.approx(flex_hz, rel=0.005)


def test_force_pulses_are_half_sines_of_0_2_to_0_5_ms(acceptance):
    _, d = acceptance
    widths = [pulse_width_s(f, float(d["fs"])) for f in d["force"]]
    assert all(0.2e-3 <= w <= 0.5e-3 for w in widths), widths
    peaks = d["force"].max(axis=1)
    assert len(set(np.round(peaks, 3))) == 3  # force varies hit to hit


def test_seeded_runs_repeat_and_balls_follow_hertz(tmp_path):
    args = ("simulate", "impacts", "--roller-type", "2", "--load-n", "80", "--impacts", "1", "--seed", "9")
    a = labctl_json(*args, "--out", str(tmp_path / "a.npz"))
    b = labctl_json(*args, "--out", str(tmp_path / "b.npz"))
    assert a["roller_stiffness_n_per_m"] == b["roller_stiffness_n_per_m"] and a["seed"] == 9
    with np.load(tmp_path / "a.npz") as x, np.load(tmp_path / "b.npz") as y:
        np.testing.assert_array_equal(x["accel"], y["accel"])
    balls = [labctl_json("simulate", "impacts", "--ball-mm", "6", "--world", "balls", "--load-n", str(f),
                         "--impacts", "1", "--seed", "1", "--out", str(tmp_path / "c.npz"))
             for f in (50, 400)]
    k = [np.mean(r["roller_stiffness_n_per_m"]) for r in balls]
    assert np.log(k[1] / k[0]) / np.log(400 / 50) == pytest.approx(1 / 3, abs=0.02)


@pytest.mark.parametrize("args, fragments", [
    (("--roller-type", "1", "--load-n", "10"), ("--load-n 10", "preload")),
    (("--roller-type", "42", "--load-n", "100"), ("roller type 42",)),
    (("--roller-type", "1", "--load-n", "100", "--impacts", "0"), ("--impacts 0",)),
    (("--roller-type", "1", "--load-n", "100", "--world", "no_such_world"), ("no_such_world", "shipped")),
    (("--roller-type", "1", "--load-n", "100", "--rail-ra-um", "-1"), ("--rail-ra-um",)),
    (("--load-n", "100",), ("--roller-type",)),
])
def test_bad_input_is_one_line_exit_2(tmp_path, args, fragments):
    proc = labctl("simulate", "impacts", *args, "--out", str(tmp_path / "x.npz"))
    assert_one_line_error(proc, *fragments)


def test_bad_world_file_and_output_path_name_the_problem(tmp_path):
    world = tmp_path / "w.toml"
    world.write_text('[baseline]\nmodel = "tripp"\n[effects.end_effects]\nedge_length_mm = 9.0\n')
    proc = labctl("simulate", "impacts", "--roller-type", "1", "--load-n", "100", "--world", str(world),
                  "--out", str(tmp_path / "x.npz"))
    assert_one_line_error(proc, str(world), "effects.end_effects.edge_length_mm = 9.0")
    proc = labctl("simulate", "impacts", "--roller-type", "1", "--load-n", "100",
                  "--out", str(tmp_path / "missing" / "x.npz"))
    assert_one_line_error(proc, "does not exist")


def test_a_ball_is_hertz_whatever_the_world_or_refused(tmp_path):
    """``--ball-mm`` alone simulates Hertz balls (world 'balls'), within 3 % of ``labctl model hertz``; a world
    whose contacts are rollers is refused, not silently used (it gave 4.6 × Hertz)."""
    truth = labctl_json("simulate", "impacts", "--ball-mm", "6", "--load-n", "100", "--impacts", "1", "--seed", "2",
                        "--out", str(tmp_path / "b.npz"))
    hertz = labctl_json("model", "hertz", "--ball-diameter-mm", "6", "--load-n", "100")
    k_hertz = hertz["stiffness_n_per_m"][0]
    assert truth["world"].endswith("balls.toml")
    assert np.mean(truth["roller_stiffness_n_per_m"]) == pytest.approx(k_hertz, rel=0.03)
    proc = labctl("simulate", "impacts", "--ball-mm", "6", "--load-n", "100", "--world", "default",
                  "--out", str(tmp_path / "c.npz"))
    assert_one_line_error(proc, "--ball-mm", "default", "balls")


def test_the_ball_acceptance_command_runs_as_written_and_writes_nothing(tmp_path, monkeypatch):
    """``labctl simulate impacts --ball-mm 6 --load-n 100`` (no --out) prints the truth it used: Hertz, no file."""
    monkeypatch.chdir(tmp_path)
    proc = labctl("simulate", "impacts", "--ball-mm", "6", "--load-n", "100")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("no file written"), proc.stdout
    line = next(x for x in proc.stdout.splitlines() if "roller stiffness" in x)
    k = [float(v) for v in line.split("roller stiffness")[1].replace("N/m", "").split(",")]
    k_hertz = labctl_json("model", "hertz", "--ball-diameter-mm", "6", "--load-n", "100")["stiffness_n_per_m"][0]
    assert np.mean(k) == pytest.approx(k_hertz, rel=0.03)
    assert list(tmp_path.iterdir()) == []


def test_hammer_level_is_a_setting_and_out_names_the_file_written(tmp_path):
    """``--hammer-level`` sets the blows' mean peak (scatter 20 % around it); ``--out`` not ending in .npz is
    refused (numpy would have written s.h5.npz while the tool printed s.h5)."""
    out = tmp_path / "h.npz"
    r = labctl_json("simulate", "impacts", "--roller-type", "1", "--load-n", "200", "--hammer-level", "60",
                    "--impacts", "3", "--seed", "4", "--out", str(out))
    assert r["hammer_level_n"] == 60 and r["out"] == str(out) and out.exists()
    with np.load(out) as d:
        peaks = d["force"].max(axis=1)
    assert np.all((peaks > 30) & (peaks < 120)), peaks
    proc = labctl("simulate", "impacts", "--roller-type", "1", "--load-n", "200", "--out", str(tmp_path / "s.h5"))
    assert_one_line_error(proc, "s.h5", ".npz")
    assert not (tmp_path / "s.h5.npz").exists() and not (tmp_path / "s.h5").exists()
    proc = labctl("simulate", "impacts", "--roller-type", "1", "--load-n", "200", "--hammer-level", "0",
                  "--out", str(tmp_path / "z.npz"))
    assert_one_line_error(proc, "--hammer-level")


def test_the_hammer_follows_the_load_unless_the_world_fixes_it(tmp_path):
    """By default the technician hits 1.0 × the load per roller (within 60-250 N); a world's ``[instruments]``
    ``peak_force_per_load = 0`` fixes the level at its ``peak_force_n``; an inverted usable range is refused."""
    from labctl.data import data_path

    r = labctl_json("simulate", "impacts", "--roller-type", "1", "--load-n", "100", "--impacts", "1", "--seed", "4",
                    "--out", str(tmp_path / "a.npz"))
    assert r["hammer_level_n"] == 100
    default = data_path("worlds/default.toml").read_text(encoding="utf-8")
    fixed, bad = tmp_path / "fixed.toml", tmp_path / "bad.toml"
    fixed.write_text(default.replace("[instruments]\n", "[instruments]\npeak_force_per_load = 0.0\n"
                                     "peak_force_n = 150.0\n"), encoding="utf-8")
    bad.write_text(default.replace("[instruments]\n", "[instruments]\npeak_force_min_n = 300.0\n"), encoding="utf-8")
    r = labctl_json("simulate", "impacts", "--roller-type", "1", "--load-n", "100", "--impacts", "1", "--seed", "4",
                    "--world", str(fixed), "--out", str(tmp_path / "b.npz"))
    assert r["hammer_level_n"] == 150
    proc = labctl("simulate", "impacts", "--roller-type", "1", "--load-n", "100", "--world", str(bad),
                  "--out", str(tmp_path / "c.npz"))
    assert_one_line_error(proc, "bad.toml", "peak_force_min_n", "300")
