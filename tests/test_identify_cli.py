"""``labctl identify`` as a user runs it: on synthetic and simulated-rig NPZ files, and on bad files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from labctl.physics import roller_stiffness_from_bounce
from tests.cli_util import assert_one_line_error, labctl, labctl_json
from tests.synth_impacts import load_rig, paper_case_modes, synth_impacts

RIG = load_rig()


@pytest.fixture(scope="module")
def synth_file(tmp_path_factory):
    s = synth_impacts(paper_case_modes(), RIG.channels, n_samples=32768, snr_db=40.0, seed=21,
                      double_hits={2: (5e-3, 0.3)})
    return s.save_npz(tmp_path_factory.mktemp("identify") / "impacts.npz")


def test_json_summary_of_a_synthetic_step(synth_file):
    out = labctl_json("identify", str(synth_file))
    assert out["bounce_hz"] == pytest.approx(745.0, abs=0.005)
    assert out["tilt_hz"] == pytest.approx([580.0, 582.0], abs=0.3)
    assert out["bounce_damping_ratio"] == pytest.approx(0.018, rel=0.003)
    assert out["roller_stiffness_n_per_m"] == pytest.approx(roller_stiffness_from_bounce(RIG, 745.0), rel=1e-4)
    assert 0.99 < out["coherence_at_bounce"] <= 1.0
    assert [(i["index"], i["accepted"], i["reasons"]) for i in out["impacts"]] == [
        (0, True, []), (1, True, []), (2, False, ["double_hit"])]


def test_whole_record_option_gives_the_same_answer(synth_file):
    trimmed = labctl_json("identify", str(synth_file))
    whole = labctl_json("identify", str(synth_file), "--whole-record")
    assert whole["bounce_hz"] != trimmed["bounce_hz"]  # other spectra, ...
    assert whole["bounce_hz"] == pytest.approx(trimmed["bounce_hz"], abs=trimmed["bounce_hz_std"])


def test_text_output_and_roller_only_stiffness(synth_file):
    proc = labctl("identify", str(synth_file), "--roller-type", "1", "--load-n", "440")
    assert proc.returncode == 0, proc.stderr
    assert "bounce  745.0" in proc.stdout
    assert "roller alone" in proc.stdout
    assert "impact 2" in proc.stdout and "rejected: double_hit" in proc.stdout


@pytest.mark.parametrize("case, fragment", [
    ("missing", "missing key 'accel'"),
    ("shape", "'force' has shape (64,)"),
    ("pickled", "holds pickled Python objects"),
])
def test_bad_npz_exits_2_with_one_line(tmp_path, case, fragment):
    path = tmp_path / f"{case}.npz"
    arrays = {"fs": np.float64(20480.0), "force": np.zeros((1, 64)), "accel": np.zeros((1, 1, 64)),
              "channels": np.array(["A1Z"])}
    if case == "missing":
        del arrays["accel"]
    elif case == "shape":
        arrays["force"] = np.zeros(64)
    else:
        arrays["channels"] = np.array([object()], dtype=object)
    np.savez(path, **arrays)
    assert_one_line_error(labctl("identify", str(path)), "labctl identify", fragment, str(path))


def test_unusable_steps_and_bad_options_exit_2(tmp_path):
    s = synth_impacts(paper_case_modes(), RIG.channels, n_samples=8192, seed=22, n_impacts=1,
                      double_hits={0: (1e-3, 0.5)})
    path = s.save_npz(tmp_path / "rejected.npz")
    assert_one_line_error(labctl("identify", str(path)), "all 1 impacts rejected", "double_hit")
    assert_one_line_error(labctl("identify", str(path), "--roller-type", "1"), "--load-n")
    assert_one_line_error(labctl("identify", str(path), "--exp-window-end", "0"), "--exp-window-end")
    assert_one_line_error(labctl("identify", str(tmp_path / "none.npz")), "file not found")


def _simulator_available() -> bool:
    return labctl("simulate", "impacts", "--help").returncode == 0


@pytest.mark.parametrize("roller_type, load_n, seed", [(1, 440.0, 5), (3, 120.0, 6)])
def test_identify_recovers_the_simulated_rigs_truth(tmp_path, roller_type, load_n, seed):
    if not _simulator_available():
        pytest.skip("labctl simulate impacts is not available")
    path = tmp_path / "sim.npz"
    truth = labctl_json("simulate", "impacts", "--roller-type", str(roller_type), "--load-n", str(load_n),
                        "--seed", str(seed), "--out", str(path))
    out = labctl_json("identify", str(path))
    # the twin's blows shift its nonlinear contact: the small-blow limit is good to its stated uncertainty
    assert abs(out["bounce_hz"] - truth["bounce_hz"]) <= max(0.05, 2 * out["bounce_hz_std"])
    assert out["bounce_hz_std"] < 5e-3 * out["bounce_hz"]
    k_true = float(np.mean(truth["roller_stiffness_n_per_m"]))
    assert out["roller_stiffness_n_per_m"] == pytest.approx(k_true, rel=0.005)
    assert all(i["accepted"] for i in out["impacts"]), json.dumps(out["impacts"])
