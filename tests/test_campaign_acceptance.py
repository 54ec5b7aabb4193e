"""The main job end to end: the demo campaign against Eq. 5, the CSV export, ball verification against Hertz."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from labctl.physics import HertzBallContact, material
from labctl.stiffness_table import read_stiffness_table
from tests.cli_util import assert_one_line_error, labctl, labctl_json

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.slow
def test_demo_matches_eq5_with_the_papers_spread_and_exports_csv(demo_campaign, tmp_path):
    campaign, out = demo_campaign  # labctl demo --json, run once for the session (tests/conftest.py)
    steps = out["steps"]
    assert len(steps) >= 10 and out["repetitions"] == 3
    assert steps[0]["load_n"] == pytest.approx(38, rel=0.05) and steps[-1]["load_n"] <= 0.31 * 1447  # C0 cap
    for s in steps:
        assert abs(s["vs_eq5"]) <= 0.10, s
    assert steps[0]["spread"] < 0.05 and steps[-1]["spread"] < 0.015

    table = tmp_path / "s.csv"
    proc = labctl("process", str(campaign), "--csv", str(table))
    assert proc.returncode == 0, proc.stderr
    with table.open(newline="") as fh:
        header = next(csv.reader(fh))
    for col in ("diameter_mm", "contact_length_mm", "rail_ra_um", "load_n", "stiffness_n_per_m", "roller_type",
                "repetition"):
        assert col in header
    points = read_stiffness_table(table)
    assert len(points) == 3 * len(steps)
    # the demo's stiffness.csv holds the stored step results: re-identifying every raw impact gives the same bytes
    assert (campaign.parent / "stiffness.csv").read_bytes() == table.read_bytes()
    assert {p.repetition for p in points} == {1, 2, 3} and {p.roller_type for p in points} == {1}
    assert points[0].diameter_m == pytest.approx(3e-3) and points[0].rail_ra_m == pytest.approx(0.2e-6)


@pytest.mark.slow
def test_ball_verification_recovers_hertz_within_one_percent(tmp_path):
    """The shipped protocol (3, 6 and 9 mm balls) at one repetition instead of two: the same steps and checks, half
    the campaign (the second repetition repeats the first's loads on the same twin)."""
    shipped = (ROOT / "protocols" / "ball_verification.toml").read_text(encoding="utf-8")
    assert "[repetitions]\ncount = 2" in shipped
    protocol = tmp_path / "ball_verification.toml"
    protocol.write_text(shipped.replace("[repetitions]\ncount = 2", "[repetitions]\ncount = 1"), encoding="utf-8")
    path = tmp_path / "balls.h5"
    run = labctl("run", str(protocol), "--backend", "sim", "--out", str(path), "--seed", "4", "--quiet")
    assert run.returncode == 0, run.stderr
    steps = labctl_json("process", str(path))["steps"]
    steel = material("1.3505")
    diameters = {1: 3e-3, 2: 6e-3, 3: 9e-3}
    assert {s["series"] for s in steps} == set(diameters) and {s["run"] for s in steps} == {1}
    for s in steps:
        hertz = float(HertzBallContact(diameters[s["series"]], steel, steel).stiffness_n_per_m(s["load_n"]))
        assert s["roller_stiffness_n_per_m"] == pytest.approx(hertz, rel=0.01), s
    slopes = []
    for series in diameters:
        pts = [(s["load_n"], s["roller_stiffness_n_per_m"]) for s in steps if s["series"] == series]
        f, k = np.log(np.array(pts)).T
        slopes.append(np.polyfit(f, k, 1)[0])
    assert slopes == pytest.approx([1 / 3] * 3, abs=0.02)  # Hertz: k ∝ F^(1/3)


def test_process_refuses_foreign_and_corrupt_files(tmp_path):
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\0" * 100)
    assert_one_line_error(labctl("process", str(junk)), "junk.h5")
    import h5py

    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["x"] = 1
    assert_one_line_error(labctl("process", str(tmp_path / "other.h5")), "not a labctl campaign")
    assert_one_line_error(labctl("process", str(tmp_path / "missing.h5")), "not found")


def test_run_refuses_to_overwrite_and_resume_needs_a_file(tmp_path):
    existing = tmp_path / "c.h5"
    existing.write_bytes(b"")
    assert_one_line_error(labctl("run", "quick_check", "--out", str(existing)), "already exists")
    assert_one_line_error(labctl("run", "quick_check", "--out", str(tmp_path / "none.h5"), "--resume"), "no campaign")
