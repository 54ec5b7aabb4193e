"""The discrepancy report an engineer reads (issue 28): where the data came from (SIMULATED for a twin campaign,
"source: CSV" for a table that cannot say), one unit per quantity with ticks that read, and the point set aside
drawn and listed."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from labctl.discrepancy import run_discrepancy
from labctl.discrepancy.report import SIM_MARK, log_ticks, sources_of, write_report
from labctl.discrepancy.synthetic import NoiseModel, synthesize
from labctl.physics import EQ5, EmpiricalFit
from labctl.stiffness_table import write_stiffness_table
from tests.cli_util import labctl

SPOILED = 5  # this point's stiffness is doubled: a gross outlier the workflow sets aside


def _eq5(case, load_n):  # noqa: ANN001, ANN202
    return EmpiricalFit(EQ5, case.roller.contact_length_m).stiffness_n_per_m(load_n)


@pytest.fixture(scope="module")
def points():  # noqa: ANN201
    pts = [p for p in synthesize(_eq5, noise=NoiseModel(0.03, 0.01), seed=21) if p.roller_type <= 2]
    pts[SPOILED] = dataclasses.replace(pts[SPOILED], stiffness_n_per_m=2.0 * pts[SPOILED].stiffness_n_per_m)
    return pts


@pytest.fixture(scope="module")
def result(points):  # noqa: ANN001, ANN201
    return run_discrepancy(points, "tripp", max_effects=1)


def _campaign_file(path, backend: str):  # noqa: ANN001, ANN202
    from labctl.storage import CampaignWriter

    CampaignWriter.create(path, protocol_name="twin", backend=backend, seed=None, config_files={},
                          description={}).close()
    return path


def test_the_point_set_aside_is_listed_with_its_load_and_stiffness_in_the_reports_units(result, points):
    spoiled = points[SPOILED]
    (aside,) = result.screening.outliers
    assert aside["load_n"] == pytest.approx(spoiled.load_n)
    assert aside["stiffness_n_per_m"] == pytest.approx(spoiled.stiffness_n_per_m)


def test_a_csv_input_says_source_csv_and_no_simulated_mark_and_lists_the_outlier(result, points, tmp_path):
    table = tmp_path / "types_1_2.csv"
    write_stiffness_table(table, points)
    files = write_report(result, tmp_path / "rep", sources=[table])
    page = (tmp_path / "rep" / "index.html").read_text(encoding="utf-8")
    assert tmp_path / "rep" / "index.html" in files
    assert "source: CSV" in page and "SIMULATED" not in page
    spoiled = points[SPOILED]
    assert f"<td>{spoiled.load_n:.1f}</td><td>{spoiled.stiffness_n_per_m * 1e-6:.2f}</td>" in page
    assert "1 gross outlier(s) set aside" in page and "red ×" in page
    for name in ("stiffness.png", "residuals.png", "steps.png", "gap.png"):
        assert f'src="{name}"' in page and (tmp_path / "rep" / name).read_bytes()[:4] == b"\x89PNG"
    assert "source: CSV" in (tmp_path / "rep" / "summary.txt").read_text(encoding="utf-8")


def test_a_twin_campaign_marks_the_page_and_a_hardware_campaign_does_not(result, tmp_path):
    twin = _campaign_file(tmp_path / "twin.h5", "sim")
    rig = _campaign_file(tmp_path / "rig.h5", "nidaq")
    assert [s.simulated for s in sources_of([twin, rig, tmp_path / "t.csv"])] == [True, False, None]
    write_report(result, tmp_path / "sim", sources=[twin])
    page = (tmp_path / "sim" / "index.html").read_text(encoding="utf-8")
    assert f"<title>Discrepancy report — {SIM_MARK}</title>" in page and "class=sim" in page
    assert "source: CSV" not in page
    write_report(result, tmp_path / "hw", sources=[rig])
    page = (tmp_path / "hw" / "index.html").read_text(encoding="utf-8")
    assert "SIMULATED" not in page and "measured (nidaq)" in page


def test_every_figure_says_simulated_has_one_unit_per_axis_and_marks_the_outlier(result, tmp_path):
    from labctl.discrepancy import report as r

    figs = {name: plot(result, tmp_path / f"{name}.png", True) for name, plot in (
        ("stiffness", r._plot_stiffness), ("residuals", r._plot_residuals), ("steps", r._plot_steps),
        ("gap", r._plot_gap))}
    for name, fig in figs.items():
        assert fig._suptitle.get_text().startswith(SIM_MARK), name
    for name in ("stiffness", "residuals", "steps"):
        visible = [ax for ax in figs[name].axes if ax.get_visible()]
        assert {ax.get_xlabel() for ax in visible} == {"load per roller [N]"}, name
        for ax in visible:  # ticks that read: at least three plain numbers on the load axis, no 10^n
            labels = [t.get_text() for t in ax.get_xticklabels()]
            lo, hi = ax.get_xlim()
            shown = [v for v in ax.get_xticks() if lo <= v <= hi]
            assert len(shown) >= 3 and not any("10^" in s or "$" in s for s in labels), (name, labels)
    stiffness = [ax for ax in figs["stiffness"].axes if ax.get_visible()]
    assert {ax.get_ylabel() for ax in stiffness} == {"roller stiffness k [N/µm]"}
    marked = [ax for ax in stiffness if "set aside (gross outlier)" in ax.get_legend_handles_labels()[1]]
    (outlier,) = result.screening.outliers
    assert [ax.get_title() for ax in marked] == [outlier["case"]]
    (line,) = [ln for ln in marked[0].get_lines() if ln.get_label() == "set aside (gross outlier)"]
    assert line.get_ydata()[0] == pytest.approx(outlier["stiffness_n_per_m"] * 1e-6)  # N/µm like the rest
    measured = next(ln for ln in marked[0].get_lines() if ln.get_label() == "measured")
    assert 1.0 < np.median(measured.get_ydata()) < 1000.0  # N/µm, not N/m
    residual_marked = [ax for ax in figs["residuals"].axes
                       if "set aside (gross outlier)" in ax.get_legend_handles_labels()[1]]
    assert len(residual_marked) == 1


@pytest.mark.parametrize(("lo", "hi", "expected"), [
    (20.0, 1000.0, [20.0, 50.0, 100.0, 200.0, 500.0, 1000.0]),  # 1-2-5 per decade
    (150.0, 400.0, [150.0, 200.0, 300.0]),  # narrower: not the lone 200 of 1-2-5, nor 10^2 and 10^3
    (31.0, 44.0, [32.0, 34.0, 36.0, 38.0, 40.0, 42.0, 44.0]),  # within a decade: round numbers, even steps
])
def test_log_ticks_read_as_plain_steps(lo: float, hi: float, expected: list[float]) -> None:
    assert log_ticks(lo, hi) == pytest.approx(expected)


def test_the_cli_report_names_a_csv_source(points, tmp_path):
    table = tmp_path / "t.csv"
    write_stiffness_table(table, points)
    proc = labctl("discrepancy", str(table), "--max-effects", "1", "--report", str(tmp_path / "rep"))
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith(f"source: {table}: source: CSV")  # the console says where the data came from
    assert "source: CSV" in (tmp_path / "rep" / "index.html").read_text(encoding="utf-8")
