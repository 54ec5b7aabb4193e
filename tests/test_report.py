"""``labctl report``: the paper's figures and the HTML page on the demo campaign; statistics; the CSV export."""

from __future__ import annotations

import csv
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import numpy as np
import pytest

from labctl.physics import EQ5, EmpiricalFit, HertzBallContact, material
from labctl.storage import CampaignReader
from tests.cli_util import assert_one_line_error, labctl, labctl_here, labctl_here_json
from tests.engine_util import short_campaign_file


@pytest.fixture(scope="module")
def demo(demo_campaign) -> tuple[Path, dict]:
    return demo_campaign  # the session's one demo run (tests/conftest.py)


@pytest.fixture(scope="module")
def short_campaign(tmp_path_factory) -> Path:
    return short_campaign_file(tmp_path_factory.mktemp("short") / "c.h5", seed=7)


def assert_not_blank_png(path: Path) -> None:
    from matplotlib.image import imread

    img = imread(path)[..., :3]
    ink = np.any(img < 0.9, axis=-1).mean()  # share of pixels that are not (near) white
    rgb = (img * 255).astype(np.uint8).reshape(-1, 3).astype(np.uint32)
    colours = np.unique(rgb[:, 0] << 16 | rgb[:, 1] << 8 | rgb[:, 2]).size  # distinct (r, g, b), one key each
    assert img.shape[0] > 300 and img.shape[1] > 400, (path, img.shape)
    assert 0.02 < ink < 0.9 and colours > 20, (path, ink, colours)


def assert_not_blank_svg(path: Path) -> None:
    root = ET.parse(path).getroot()
    ns = "{http://www.w3.org/2000/svg}"
    paths = [p for p in root.iter(f"{ns}path") if len(p.get("d", "")) > 20]
    assert len(paths) > 20, (path, len(paths))


@pytest.mark.slow  # shares the demo campaign (~25 s to make)
def test_report_on_the_demo_campaign_writes_every_figure_and_the_page(demo, tmp_path, capsys):
    campaign, _ = demo
    out = tmp_path / "report"
    res = labctl_here_json(capsys, "report", str(campaign), "--out", str(out))
    names = [f["name"] for f in res["figures"]]
    assert names == ["fig08_load_stiffness", "fig12_models_ra0.2", "fig07_frf_s01_r01_step011", "frequency_load"]
    page = Path(res["html"]).read_text(encoding="utf-8")
    for f in res["figures"]:
        png, svg = Path(f["png"]), Path(f["svg"])
        assert png.stat().st_size > 10_000 and svg.stat().st_size > 10_000
        assert_not_blank_png(png)
        assert_not_blank_svg(svg)
        assert f'href="{png.name}"' in page and f'href="{svg.name}"' in page
    assert page.count("data:image/png;base64,") == len(names)  # readable without the folder
    with CampaignReader(campaign) as reader:  # the twin's blows are sometimes rejected: count them from the file
        infos = [i for run in reader.runs(1) for st in run.steps for i in st.impacts]
    accepted = sum(i.accepted for i in infos)
    counts = f"{accepted} impacts accepted, {len(infos) - accepted} rejected"
    for section in ("Protocol", "Rig", "World", "Impacts", "roller_stiffness", counts):
        assert section in page
    assert accepted == 99 and res["impacts"]["accepted"] == 99 and res["impacts"]["rejected"] == len(infos) - 99
    assert Path(res["csv"]).name == "stiffness.csv" and 'href="stiffness.csv"' in page
    assert res["simulated"] and "SIMULATED" in page and "<title>SIMULATED" in page
    assert "Verdict against the model band" in page and "Rig and model parameters" in page
    assert len(res["verdicts"]) == 11 and {v["model"] for v in res["verdicts"]} == {"Eq. 5"}
    assert all(v["verdict"] in ("pass", "fail", "cannot tell") for v in res["verdicts"])


@pytest.mark.slow  # shares the demo campaign (~25 s to make)
def test_report_statistics_agree_with_the_demo_summary(demo):
    from labctl.report.data import load_report_data

    campaign, summary = demo
    stats = load_report_data(campaign).series[0].step_stats()
    assert len(stats) == len(summary["steps"])
    for got, want in zip(stats, summary["steps"], strict=True):
        assert got.load_n == pytest.approx(want["load_n"], rel=1e-9)
        assert got.stiffness_n_per_m == pytest.approx(want["stiffness_n_per_m"], rel=1e-9)
        assert got.spread == pytest.approx(want["spread"], rel=1e-9)


@pytest.mark.slow  # shares the demo campaign (~25 s to make)
def test_models_figure_draws_eq5_and_the_measured_means_per_contact_length(demo):
    from labctl.report.data import load_report_data
    from labctl.report.figures import models

    series = load_report_data(demo[0]).series[0]
    length = series.case.roller.contact_length_m
    ax = models([series], "fit-ra0.2").axes[0]
    fit = next(line for line in ax.get_lines() if line.get_label() == "Eq. 5 fit")
    p = np.asarray(fit.get_xdata()) * 1e3  # N/mm → N/m
    want = EmpiricalFit(EQ5, length).stiffness_n_per_m(p * length) / length * 1e-9  # N/µm per mm
    np.testing.assert_allclose(fit.get_ydata(), want, rtol=1e-12)
    means = ax.containers[0].lines[0]  # the error-bar markers: mean stiffness per step
    stats = series.step_stats()
    np.testing.assert_allclose(means.get_ydata(), [s.stiffness_n_per_m / length * 1e-9 for s in stats])


@pytest.mark.slow  # shares the demo campaign (~25 s to make)
def test_stiffness_csv_opens_cleanly_in_a_spreadsheet(demo):
    table = Path(demo[1]["csv"])  # written like `labctl process --csv`: reprocessed points, the table writer
    raw = table.read_bytes()
    assert not raw.startswith(b"\xef\xbb\xbf") and b"\r\n" in raw  # RFC 4180 rows, no byte-order mark
    with table.open(newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    header, body = rows[0], rows[1:]
    assert header[0] == "diameter_mm" and all(h.isascii() and h.strip() == h and h for h in header)
    units = ("_mm", "_um", "_n", "_n_per_m", "_gpa")
    unitless = {"roller_type", "material", "poisson_ratio", "hardness_hrc", "repetition", "rail_material"}
    assert all(h.endswith(units) or h in unitless for h in header), header
    assert len(body) == 33 and all(len(r) == len(header) for r in body)
    for r in body:
        for h, cell in zip(header, r, strict=True):
            if h not in ("material", "rail_material"):
                float(cell)  # every numeric cell is a plain number, no index or unit text


def test_rejected_impacts_and_reasons_in_the_statistics_and_page(short_campaign, tmp_path, capsys):
    import json

    campaign = tmp_path / "c.h5"
    shutil.copy(short_campaign, campaign)
    with h5py.File(campaign, "r+") as f:
        step = f["series_01/run_02/step_001"]
        imp = step["impact_002"]
        imp.attrs["accepted"], imp.attrs["reasons"] = False, json.dumps(["double_hit"])
        result = step["result"]
        late = json.loads(result.attrs["impacts"])
        late[0]["accepted"], late[0]["reasons"] = False, ["low_coherence"]
        result.attrs["impacts"] = json.dumps(late)
    res = labctl_here_json(capsys, "report", str(campaign), "--out", str(tmp_path / "r"), "--frf-step", "1:2:1")
    assert res["impacts"]["rejected"] == 2 and res["impacts"]["by_reason"] == {"double_hit": 1, "low_coherence": 1}
    page = Path(res["html"]).read_text(encoding="utf-8")
    assert "double_hit" in page and "low_coherence" in page
    assert "fig07_frf_s01_r02_step001" in [f["name"] for f in res["figures"]]


def test_ball_campaigns_are_shown_against_hertz(tmp_path):
    from labctl.physics.effects import ContactCase
    from labctl.physics.rig_config import load_rig
    from labctl.report.data import ImpactStats, ReportData, RunCurve, SeriesData
    from labctl.report.figures import make_figures

    steel = material("1.3505")
    case = ContactCase(__import__("labctl.physics", fromlist=["Roller"]).Roller(6e-3, 6e-3, 6e-3, steel), steel,
                       0.2e-6)
    f = np.linspace(40, 400, 8)
    k = HertzBallContact(6e-3, steel, steel).stiffness_n_per_m(f)
    run = RunCurve(1, np.arange(1, 9), f, k, np.full(8, 600.0), np.full((8, 2), 450.0))
    series = SeriesData(1, "ball 6 mm", "ball", {}, case, [run])
    data = ReportData(tmp_path / "x.h5", {}, [series], ImpactStats(), None, {}, load_rig(), [])
    plots = {p.name: p for p in make_figures(data)}
    assert set(plots) == {"fig08_load_stiffness", "verification_hertz", "frequency_load"}
    hertz = next(line for line in plots["verification_hertz"].figure.axes[0].get_lines()
                 if line.get_label().startswith("Hertz"))
    want = HertzBallContact(6e-3, steel, steel).stiffness_n_per_m(hertz.get_xdata()) * 1e-6  # N/µm
    np.testing.assert_allclose(hertz.get_ydata(), want, rtol=1e-12)


def test_report_errors_are_one_line(short_campaign, tmp_path, capsys):
    cut = tmp_path / "cut.h5"
    cut.write_bytes(short_campaign.read_bytes()[:4096])
    assert_one_line_error(labctl("report", str(cut), "--out", str(tmp_path / "r")), "cut.h5")
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\0" * 100)
    out = str(tmp_path / "r")
    assert_one_line_error(labctl_here(capsys, "report", str(junk), "--out", out), "junk.h5")
    assert_one_line_error(labctl_here(capsys, "report", str(short_campaign), "--out", out, "--frf-step", "x"),
                          "--frf-step")
    assert_one_line_error(labctl_here(capsys, "report", str(short_campaign), "--out", out, "--frf-step", "1:9:1"),
                          "run 9")
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert_one_line_error(labctl_here(capsys, "report", str(short_campaign), "--out", str(blocker)), "not a folder")
    assert_one_line_error(labctl_here(capsys, "report", str(short_campaign), "--out", out, "--band", "0"), "--band")


def test_band_option_sets_the_verdicts_band(short_campaign, tmp_path, capsys):
    tight = labctl_here_json(capsys, "report", str(short_campaign), "--out", str(tmp_path / "t"), "--band", "0.01")
    wide = labctl_here_json(capsys, "report", str(short_campaign), "--out", str(tmp_path / "w"), "--band", "90")
    assert {v["band"] for v in tight["verdicts"]} == {0.0001} and {v["band"] for v in wide["verdicts"]} == {0.9}
    judged = [v for v in wide["verdicts"] if v["model"]]
    assert judged and all(v["verdict"] == "pass" for v in judged)
    assert all(v["verdict"] in ("fail", "cannot tell") for v in tight["verdicts"] if v["model"])


def _series(k_factor: float, scatter: float = 0.0, roller_type: int = 1, runs: int = 3):
    """A roller series whose repetitions measure k_factor × Eq. 5 (± scatter, alternating)."""
    from labctl.physics import EQ5, EmpiricalFit, material, roller
    from labctl.physics.effects import ContactCase
    from labctl.report.data import RunCurve, SeriesData

    r = roller(roller_type)
    case = ContactCase(r, material("1.3505"), 0.2e-6)
    f = np.linspace(60, 400, 5)
    k = EmpiricalFit(EQ5, r.contact_length_m).stiffness_n_per_m(f) * k_factor
    curves = [RunCurve(i + 1, np.arange(1, 6), f, k * (1 + scatter * (-1) ** i), np.full(5, 700.0),
                       np.full((5, 2), 550.0)) for i in range(runs)]
    return SeriesData(1, f"roller type {roller_type}", "roller", {}, case, curves)


def test_verdicts_pass_fail_and_cannot_tell_follow_the_stated_rule():
    from labctl.physics.rig_config import load_rig
    from labctl.report.verdict import series_verdicts

    rig = load_rig()
    assert {v.verdict for v in series_verdicts(_series(1.02), rig)} == {"pass"}
    assert {v.verdict for v in series_verdicts(_series(1.30), rig)} == {"fail"}
    assert {v.verdict for v in series_verdicts(_series(0.75), rig)} == {"fail"}
    # mean 9 % high but repetitions ±10 % apart: the 95 % interval straddles the band edge
    assert {v.verdict for v in series_verdicts(_series(1.09, scatter=0.10), rig)} == {"cannot tell"}
    assert {v.verdict for v in series_verdicts(_series(1.09), rig, band=0.05)} == {"fail"}
    si3n4 = series_verdicts(_series(1.0, roller_type=8), rig)
    assert {v.verdict for v in si3n4} == {"no verdict"} and "steel" in si3n4[0].note


def test_rig_uncertainty_propagates_like_eq4():
    """d ln k / d ln m = 3k/K_total and d ln k / d ln K_setup = -3k/K_setup for 1/K_total = 1/(3k) + 1/K_setup."""
    from dataclasses import replace

    from labctl.physics.rig_config import RigUncertainty, load_rig
    from labctl.report.verdict import rig_relative_std

    rig = load_rig()
    k = 4.5e7
    m, ks = rig.upper.mass_kg, rig.setup_stiffness_n_per_m
    k_total = 1 / (1 / (3 * k) + 1 / ks)
    only_mass = replace(rig, uncertainty=RigUncertainty(mass_std_kg=0.01 * m))
    assert rig_relative_std(only_mass, k) == pytest.approx(3 * k / k_total * 0.01, rel=0.05)
    only_setup = replace(rig, uncertainty=RigUncertainty(setup_stiffness_std_n_per_m=0.1 * ks))
    assert rig_relative_std(only_setup, k) == pytest.approx(3 * k / ks * 0.1, rel=0.1)
    assert rig_relative_std(replace(rig, uncertainty=RigUncertainty(model_rel=0.003)), k) == pytest.approx(0.003)


def test_report_states_the_rig_uncertainty_of_the_steps_own_budget():
    """The report's rig share of a stiffness's uncertainty is the one `identify` and the stiffness table state
    (the budget's disc mass, K_setup and model terms), not a second propagation of its own."""
    import math

    from labctl.physics.rig_config import load_rig
    from labctl.processing.stiffness import stiffness_budget
    from labctl.report.verdict import rig_relative_std

    rig = load_rig()
    for k in (2.2e7, 4.5e7, 9e7):
        budget = stiffness_budget(rig, k, 0.002 * k)
        rig_share = math.sqrt(budget.total_std_n_per_m**2 - budget.terms["modal_fit"] ** 2)
        assert rig_relative_std(rig, k) * k == pytest.approx(rig_share, rel=1e-9)


def test_simulated_figures_say_so_and_use_n_per_um(tmp_path):
    from labctl.physics.rig_config import load_rig
    from labctl.report.data import ImpactStats, ReportData
    from labctl.report.figures import make_figures

    series = [_series(1.0), _series(1.0, roller_type=8)]
    series[1].index = 2
    for attrs, marked in (({"backend": "sim"}, True), ({"backend": "hw"}, False)):
        data = ReportData(tmp_path / "x.h5", attrs, series, ImpactStats(), None, {}, load_rig(), [])
        for plot in make_figures(data):
            title = plot.figure.get_suptitle()
            assert ("SIMULATED" in title) == marked, (plot.name, title)
            for ax in plot.figure.axes:
                assert "1e" not in ax.yaxis.get_offset_text().get_text()
    models = next(p for p in make_figures(data) if p.name.startswith("fig12")).figure
    assert len([ax for ax in models.axes if ax.get_visible()]) == 2  # steel and Si3N4 apart
    si3n4 = next(ax for ax in models.axes if "Si3N4" in ax.get_title())
    assert not any(line.get_label() == "Eq. 5 fit" for line in si3n4.get_lines())
