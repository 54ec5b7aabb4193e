"""Spring stacks (the paper's §2.6): the twin's springs, their characterisation and fit, the rig file's [springs]
curve, and a campaign with ``load_source = "springs"`` that never touches a load cell."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from drivers.sim import twin_of
from labctl.backends import make_rig
from labctl.calibration.spring_run import characterise, load_spring_protocol, parse_spring_protocol
from labctl.calibration.springs import SpringData, fit_spring_curve, rig_text_with_springs
from labctl.campaign import rig_factory
from labctl.engine import Engine
from labctl.errors import InputError
from labctl.physics import ContactCase, load_rig, material, roller
from labctl.physics.rig_config import rig_from_text
from labctl.protocol import parse_protocol
from labctl.stiffness_table import read_stiffness_table, write_stiffness_table
from labctl.storage.memory import MemoryStore

WORLD = "springs"
CASE = ContactCase(roller(1), material("1.3505"), 0.2e-6)
PAPER_RIG = Path(load_rig().source).read_text(encoding="utf-8")
PROTOCOL = """
[protocol]
name = "springs_short"
[specimen]
roller_type = 1
rail_ra_um = 0.2
max_load_n = 300.0
knob_step_deg = 360.0
[acquisition]
samples = 16384
impacts_per_step = 2
[loading]
settle_poll_s = 0.0
{extra}
[repetitions]
count = 2
"""


def twin(seed: int = 3, world: str = WORLD):
    return twin_of(make_rig("sim", case=CASE, world=world, seed=seed))


@pytest.fixture(scope="module")
def curve():
    rig = make_rig("sim", case=CASE, world=WORLD, seed=11)
    return fit_spring_curve(characterise(rig, load_spring_protocol("protocols/spring_characterisation.toml"), 3))


def test_twin_springs_have_slack_nonlinearity_hysteresis_and_rod_differences():
    t = twin()
    s = t.springs
    assert s is not None and len(set(np.round(s.rates))) == 4  # rods differ
    assert np.std(s.rates) / np.mean(s.rates) < 0.1
    t.turn_knobs(float(s.slack_deg.min()) - 1.0)
    assert t.load_per_roller_n() == pytest.approx(t.preload_n)  # the first turn only takes up slack
    t.turn_knobs(-t.knob_angle_deg)
    loads = []
    for _ in range(12):
        t.turn_knobs(180.0)
        loads.append(t.load_per_roller_n())
    steps = np.diff(loads)
    assert steps[-1] > steps[1] * 1.03  # progressive: the last half turn adds more than an early one
    up = loads[5]
    t.turn_knobs(-6 * 180.0)
    assert t.knob_angle_deg == pytest.approx(1080.0)
    assert t.load_per_roller_n() - up == pytest.approx(float(s.band_n.sum()) / 3, rel=0.01)  # unloading above
    # the springs belong to the rig: another seed of the same world has the same ones; the default world none
    assert np.array_equal(twin(seed=99).springs.rates, s.rates)
    assert twin(world="default").springs is None
    t.set_load_per_roller(300.0)  # a test hook puts the rig at a load through the same springs (loading branch)
    assert t.load_per_roller_n() == pytest.approx(300.0)


def test_fit_recovers_the_twins_springs_and_its_sigma_covers_the_truth(curve):
    t = twin(seed=21)
    errors = []
    for _ in range(6):  # fresh seatings: each draws new nut slack, which the curve's σ must cover
        t.rotate_rollers()
        for angle in (360.0, 1080.0, 1800.0):
            t.turn_knobs(angle - t.knob_angle_deg)
            errors.append((curve.load_n(angle) - t.load_per_roller_n()) / curve.load_std_n(angle))
            t.turn_knobs(-t.knob_angle_deg)
    errors = np.abs(errors)
    assert errors.max() < 3.0 and np.mean(errors < 1.0) > 0.5
    assert curve.hysteresis_n == pytest.approx(float(t.springs.band_n.sum()) / 3, rel=0.1)
    nominal = load_rig().load_per_knob_degree_n
    assert curve.rate_n_per_deg == pytest.approx(nominal, rel=0.06)
    assert curve.curvature_n_per_deg2 > 0


def test_fit_refuses_one_branch_or_no_preload():
    a = np.array([0.0, 0.0, *np.arange(90.0, 1900.0, 90.0)])
    f = 38 + 0.22 * a
    with pytest.raises(InputError, match="loading and unloading"):
        fit_spring_curve(SpringData(a, f, np.ones_like(a), "x.h5"))
    with pytest.raises(InputError, match="knob angle 0"):
        fit_spring_curve(SpringData(a[2:], f[2:], np.ones(a.size - 2), "x.h5"))


def test_springs_table_round_trips_and_bad_fields_are_named(curve):
    text = rig_text_with_springs(PAPER_RIG, "rig.toml", curve, "s.h5")
    back = rig_from_text(text, "rig.toml").springs
    assert back is not None and back.rate_n_per_deg == curve.rate_n_per_deg
    assert back.load_std_n(900.0) == pytest.approx(curve.load_std_n(900.0))
    again = rig_text_with_springs(text, "rig.toml", curve, "t.h5")  # replaces, does not duplicate
    assert again.count("[springs]") == 1 and 's.h5' not in again
    bad = text.replace("covariance = [", "covariance = [1.0, ")
    with pytest.raises(InputError, match="springs.*covariance"):
        rig_from_text(bad, "rig.toml")


def test_characterisation_protocol_is_validated_and_not_a_campaign():
    good = Path("protocols/spring_characterisation.toml").read_text()
    p = parse_spring_protocol(good, "s.toml")
    assert p.angles_deg()[0] == 90.0 and p.angles_deg()[-1] == 0.0 and max(p.angles_deg()) == 2160.0
    with pytest.raises(InputError, match="characterisation.knob_step_deg"):
        parse_spring_protocol(good.replace("knob_step_deg = 90.0", "knob_step_deg = 9000.0"), "s.toml")
    with pytest.raises(InputError, match="labctl springs characterise"):
        parse_protocol(good, "s.toml")


class NoLoadCell:
    """A rig without a load cell: any use of it fails the test."""

    def __getattr__(self, name: str):
        raise AssertionError(f"the load cell was used ({name}) in a load_source = 'springs' campaign")


def run(rig_config, extra: str, *, no_cell: bool) -> MemoryStore:
    proto = parse_protocol(PROTOCOL.format(extra=extra), "p.toml")
    make = rig_factory("sim", rig_config, world=WORLD, seed=5)

    def factory(spec, series):
        rig = make(spec, series)
        return dataclasses.replace(rig, load_cell=NoLoadCell()) if no_cell else rig

    store = MemoryStore()
    assert Engine(proto, rig_config, factory, store).run().status == "complete"
    return store


def test_a_springs_campaign_needs_no_load_cell_and_matches_the_load_cell_campaign(curve, tmp_path):
    rig_config = rig_from_text(rig_text_with_springs(PAPER_RIG, "rig.toml", curve, "s.h5"), "rig.toml")
    cell = run(rig_config, "", no_cell=False).stiffness_points()
    springs = run(rig_config, 'load_source = "springs"', no_cell=True).stiffness_points()
    assert len(cell) == len(springs) >= 4
    assert all(p.load_std_n is None for p in cell)
    for rep in (1, 2):
        a = [p for p in cell if p.repetition == rep]
        b = [p for p in springs if p.repetition == rep]
        fa, ka = np.log([p.load_n for p in a]), np.log([p.stiffness_n_per_m for p in a])
        for p in b:
            assert p.load_std_n == pytest.approx(curve.load_std_n(0.0), rel=0.2)
            k_cell = np.exp(np.interp(np.log(p.load_n), fa, ka))  # the load-cell curve at the springs' load
            assert p.stiffness_n_per_m == pytest.approx(k_cell, rel=0.02)
        loads_a, loads_b = np.array([p.load_n for p in a]), np.array([p.load_n for p in b])
        assert np.all(np.abs(loads_b - loads_a) < 3 * np.array([p.load_std_n for p in b]))
    out = tmp_path / "table.csv"
    write_stiffness_table(out, springs)
    assert "load_std_n" in out.read_text().splitlines()[0]
    assert [p.load_std_n for p in read_stiffness_table(out)] == pytest.approx([p.load_std_n for p in springs])


def test_a_springs_campaign_without_a_curve_or_beyond_it_is_refused():
    proto = parse_protocol(PROTOCOL.format(extra='load_source = "springs"'), "p.toml")
    with pytest.raises(InputError, match=r"no \[springs\] table"):
        Engine(proto, load_rig(), rig_factory("sim", load_rig(), world=WORLD), MemoryStore())


def test_cli_characterise_fit_and_a_springs_campaign_file(tmp_path, capsys):
    from labctl.campaign import run_campaign
    from labctl.cli import main
    from labctl.storage import campaign_stiffness_points

    readings, rig = tmp_path / "springs.h5", tmp_path / "rig.toml"
    assert main(["springs", "characterise", "protocols/spring_characterisation.toml", "--world", WORLD,
                 "--seed", "11", "--out", str(readings)]) == 0
    assert main(["springs", "characterise", "protocols/spring_characterisation.toml", "--out", str(readings)]) == 2
    assert "never overwrites" in capsys.readouterr().err
    assert main(["springs", "fit", str(readings), "--out", str(readings)]) == 2  # an input is never an output
    assert main(["springs", "fit", str(readings), "--out", str(rig), "--json"]) == 0
    fitted = __import__("json").loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert fitted["rig_out"] == str(rig) and load_rig(rig).springs is not None
    proto = parse_protocol(PROTOCOL.format(extra='load_source = "springs"').replace("count = 2", "count = 1"),
                           "p.toml")
    out = tmp_path / "c.h5"
    assert run_campaign(proto, out=out, world=WORLD, seed=5, rig=rig).status == "complete"
    points = campaign_stiffness_points(out)
    assert points and all(0 < p.load_std_n < 2.0 for p in points)
    assert main(["springs", "fit", str(out)]) == 2
    assert "not a spring characterisation file" in capsys.readouterr().err


def test_a_devices_file_without_a_load_cell_runs_springs_campaigns_only(tmp_path):
    import re

    from drivers.errors import DeviceError
    from labctl.campaign import run_campaign
    from labctl.hardware import load_devices

    example = Path("labctl/data/devices.example.toml").read_text(encoding="utf-8")
    devices = tmp_path / "devices.toml"
    devices.write_text(re.sub(r"\[load_cell\].*?\n\n", "", example, count=1, flags=re.S), encoding="utf-8")
    specs = load_devices(devices)
    assert specs["load_cell"].kind == "none"
    cell = specs["load_cell"].build(None)
    with pytest.raises(DeviceError, match="no \\[load_cell\\]"):
        cell.read()
    out = tmp_path / "c.h5"
    with pytest.raises(InputError, match="no \\[load_cell\\]"):
        run_campaign(parse_protocol(PROTOCOL.format(extra=""), "p.toml"), out=out, backend="hw", devices=devices)
    assert not out.exists()


def test_the_report_shows_the_spring_loads_sigma(tmp_path, curve):
    from labctl.campaign import run_campaign
    from labctl.report import build_report

    rig = tmp_path / "rig.toml"
    rig.write_text(rig_text_with_springs(PAPER_RIG, "rig.toml", curve, "s.h5"), encoding="utf-8")
    proto = parse_protocol(PROTOCOL.format(extra='load_source = "springs"').replace("count = 2", "count = 1"),
                           "p.toml")
    run_campaign(proto, out=tmp_path / "c.h5", world=WORLD, seed=5, rig=rig)
    result = build_report(tmp_path / "c.h5", tmp_path / "report")
    page = Path(result.html).read_text(encoding="utf-8")
    assert "load ± 1-σ (spring curve) [N]" in page and f"± {curve.load_std_n(360.0):.1f}" in page
    assert "load_std_n" in Path(result.csv).read_text(encoding="utf-8").splitlines()[0]


def test_a_springs_campaign_on_hardware_drivers_without_a_load_cell(tmp_path, curve, monkeypatch):
    """The MCC DAQ and serial hammer of the hardware path (emulated, fed by the twin), no [load_cell] at all."""
    import re

    from labctl import campaign
    from tests.test_hw_engine import TwinBench

    bench = TwinBench(tmp_path)
    try:
        text = bench.devices.read_text(encoding="utf-8")
        bench.devices = tmp_path / "no_cell.toml"
        bench.devices.write_text(re.sub(r"\[load_cell\].*?\n\n", "", text, count=1, flags=re.S), encoding="utf-8")
        rig = tmp_path / "rig.toml"
        rig.write_text(rig_text_with_springs(PAPER_RIG, "rig.toml", curve, "s.h5"), encoding="utf-8")
        proto = parse_protocol(Path("protocols/quick_check.toml").read_text(encoding="utf-8")
                               + '\n[loading]\nload_source = "springs"\n', "qs.toml")
        sim = campaign.run_campaign(proto, out=tmp_path / "sim.h5", backend="sim", seed=11, rig=rig)
        monkeypatch.setattr(campaign, "make_rig", bench.make_rig)
        hw = campaign.run_campaign(proto, out=tmp_path / "hw.h5", backend="hw", seed=11, rig=rig,
                                   devices=bench.devices)
        assert sim.status == "complete" and hw.status == "complete", (sim.message, hw.message)
        s, h = sim.curves[0], hw.curves[0]
        np.testing.assert_allclose(h["load_n"], s["load_n"], rtol=1e-12)  # both from the spring curve
        np.testing.assert_allclose(h["stiffness_n_per_m"], s["stiffness_n_per_m"], rtol=2e-4)
    finally:
        bench.stop()
