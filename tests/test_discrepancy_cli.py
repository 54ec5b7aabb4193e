"""``labctl discrepancy`` as a user runs it: CSV files in, one JSON object or a summary out, a report folder,
and one-line errors for malformed input."""

from __future__ import annotations

import pytest

from labctl.discrepancy.synthetic import NoiseModel, synthesize
from labctl.physics import EQ5, EmpiricalFit, SurfaceRoughness
from labctl.stiffness_table import write_stiffness_table
from tests.cli_util import assert_one_line_error, labctl, labctl_json
from tests.discrepancy_util import world

HEADER = "diameter_mm,contact_length_mm,rail_ra_um,load_n,stiffness_n_per_m\n"


def _eq5(case, load_n):
    return EmpiricalFit(EQ5, case.roller.contact_length_m).stiffness_n_per_m(load_n)


@pytest.fixture(scope="module")
def eq5_tables(tmp_path_factory):
    """Eq. 5 data for types 1-7 split over two files, as two campaigns would deliver them."""
    folder = tmp_path_factory.mktemp("eq5")
    points = synthesize(_eq5, noise=NoiseModel(0.03, 0.01), seed=21)
    first = folder / "types_1_3.csv"
    second = folder / "types_4_7.csv"
    write_stiffness_table(first, [p for p in points if p.roller_type <= 3])
    write_stiffness_table(second, [p for p in points if p.roller_type > 3])
    return first, second


@pytest.fixture(scope="module")
def rough_tables(tmp_path_factory):
    """The twin's roughness (asperity scale 1.5 on Tripp at 1.5 mm) for types 1-7 on two rails, a file each (on
    one rail roughness cannot be told from a rig joint that closes with load, and is not named)."""
    folder = tmp_path_factory.mktemp("rough")
    truth = world(SurfaceRoughness(1.5), depth_m=1.5e-3)
    first, second = folder / "rail_ra_0.2.csv", folder / "rail_ra_0.03.csv"
    write_stiffness_table(first, synthesize(truth, noise=NoiseModel(0.03, 0.01), seed=21))
    write_stiffness_table(second, synthesize(truth, rail_ra_m=0.03e-6, noise=NoiseModel(0.03, 0.01), seed=22))
    return first, second


def test_json_names_roughness_and_reports_the_gap_per_step(rough_tables, tmp_path):
    report = tmp_path / "report"
    out = labctl_json("discrepancy", *map(str, rough_tables), "--report", str(report))
    assert {"baseline", "gap_before", "gap_after", "noise_floor", "effects", "regions"} <= out.keys()
    assert out["baseline"] == "tripp" and out["n_points"] == 462 and out["n_cases"] == 14
    assert [e["name"] for e in out["effects"]] == ["surface_roughness"]
    step = out["effects"][0]
    assert {"name", "parameters", "evidence", "gap_before", "gap_after"} <= step.keys()
    assert step["gap_before"] == out["gap_before"] >= 0.15
    assert step["gap_after"] == out["gap_after"] <= 0.02
    assert step["evidence"]["delta_bic"] >= 10 and step["evidence"]["probability"] >= 0.9
    assert out["explanations"][0]["explanation"] == "surface_roughness"
    assert sum(x["probability"] for x in out["explanations"]) == pytest.approx(1.0)
    assert 0.005 < out["noise_floor"] < 0.04
    for name in ("stiffness.png", "residuals.png", "gap.png", "steps.png", "discrepancy.json", "summary.txt"):
        assert (report / name).stat().st_size > 500, name
    assert (report / "stiffness.png").read_bytes()[:4] == b"\x89PNG"


def test_text_summary(eq5_tables):
    proc = labctl("discrepancy", str(eq5_tables[0]), str(eq5_tables[1]))
    assert proc.returncode == 0, proc.stderr
    assert "surface_roughness" in proc.stdout and "consistent with the noise" in proc.stdout
    assert "model stiffer" in proc.stdout


def test_another_baseline(eq5_tables):
    out = labctl_json("discrepancy", *map(str, eq5_tables), "--baseline", "fit-ra0.2")
    assert out["baseline"] == "fit-ra0.2" and out["effects"] == [] and out["gap_before"] < 0.05


@pytest.mark.parametrize(
    ("text", "fragments"),
    [
        ("diameter_mm,contact_length_mm,rail_ra_um,stiffness_n_per_m\n3,1.793,0.2,4e7\n",
         ["missing column", "load_n"]),
        (HEADER + "3,1.793,0.2,100,4e7\n3,1.793,0.2,12O,4.2e7\n", ["row 3", "load_n", "'12O'"]),
        (HEADER + "3,1.793,0.2,-40,4e7\n", ["row 2", "load_n", "'-40'"]),
    ],
    ids=["missing-column", "text-in-number", "negative-load"],
)
def test_malformed_csv_exits_2_with_one_line(tmp_path, text, fragments):
    path = tmp_path / "bad.csv"
    path.write_text(text, encoding="utf-8")
    assert_one_line_error(labctl("discrepancy", str(path)), "bad.csv", *fragments)
    assert_one_line_error(labctl("discrepancy", str(path), "--json"), "bad.csv", *fragments)


def test_other_bad_invocations_exit_2_with_one_line(tmp_path, eq5_tables):
    assert_one_line_error(labctl("discrepancy", str(tmp_path / "none.csv")), "file not found")
    assert_one_line_error(labctl("discrepancy", str(eq5_tables[0]), "--baseline", "magic"), "magic")
    assert_one_line_error(labctl("discrepancy", str(eq5_tables[0]), "--max-effects", "9"), "--max-effects")
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert_one_line_error(labctl("discrepancy", str(eq5_tables[0]), "--report", str(blocker)), "--report")


def test_a_file_that_is_no_campaign_is_a_one_line_error(tmp_path):
    path = tmp_path / "campaign.h5"
    path.write_bytes(b"not hdf5")
    assert_one_line_error(labctl("discrepancy", str(path)), "campaign.h5")
    assert_one_line_error(labctl("discrepancy", str(tmp_path / "missing.hdf5")), "missing.hdf5", "not found")


def _campaign(path, points, rig_text):
    """A campaign file holding only processed step results (as the engine stores them) and its rig."""
    from labctl.storage import CampaignWriter, StepResult
    from labctl.storage.specimen import SpecimenRecord

    types = sorted({p.roller_type for p in points})
    with CampaignWriter.create(path, protocol_name="t", backend="sim", seed=1, config_files={"rig.toml": rig_text},
                               description={}) as w:
        for series, t in enumerate(types, 1):
            mine = [p for p in points if p.roller_type == t]
            p0 = mine[0]
            w.series(series, SpecimenRecord(label=f"type {t}", roller_type=t, diameter_m=p0.diameter_m,
                                            contact_length_m=p0.contact_length_m, roller_length_m=p0.roller_length_m,
                                            rail_ra_m=p0.rail_ra_m, material="1.3505", rail_material="1.3505"))
            for rep in sorted({p.repetition for p in mine}):
                w.run(series, rep)
                for step, p in enumerate([q for q in mine if q.repetition == rep], 1):
                    w.step(series, rep, step, {"load_n": p.load_n})
                    w.write_step_result(series, rep, step, StepResult(roller_stiffness_n_per_m=p.stiffness_n_per_m))


def test_a_campaign_file_is_analysed_with_the_rig_stored_in_it(tmp_path):
    from labctl.data import data_path

    text = data_path("rigs/paper_rig.toml").read_text(encoding="utf-8")
    stored = text.replace("setup_stiffness_n_per_m = 1.45e9", "setup_stiffness_n_per_m = 2.9e9")
    assert stored != text
    path = tmp_path / "c.h5"
    _campaign(path, synthesize(_eq5, types=[1, 4, 6], noise=NoiseModel(0.03, 0.01), seed=22), stored)
    out = labctl_json("discrepancy", str(path))
    assert out["nominal_setup_stiffness_n_per_m"] == 2.9e9 and out["n_cases"] == 3
    assert out["sources"] == [f"{path}: campaign file, SIMULATED (digital twin)"]  # a twin campaign says so
    assert {e["name"] for e in out["effects"]} <= {"surface_roughness"} and out["measurement_effects"] == []
    rig = tmp_path / "rig.toml"
    rig.write_text(text, encoding="utf-8")
    assert labctl_json("discrepancy", str(path), "--rig", str(rig))["nominal_setup_stiffness_n_per_m"] == 1.45e9
