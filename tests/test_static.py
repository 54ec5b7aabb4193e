"""The static load–displacement method (§2.5): sensor, protocol table, slope processing, engine and figure."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from drivers.errors import DeviceDisconnected
from drivers.sim.displacement import DisplacementSettings, SimDisplacementSensor
from labctl.backends import make_rig
from labctl.campaign import run_campaign
from labctl.errors import InputError, ModelDomainError
from labctl.physics.rig import roller_path_stiffness, roller_stiffness_from_path
from labctl.processing.static import StaticPoint, static_stiffness
from labctl.protocol import load_protocol, parse_protocol
from labctl.report.static_figure import compare

ROOT = Path(__file__).resolve().parent.parent
K_SETUP = 1.45e9
SMALL = """
[specimen]
roller_type = 1
max_load_n = 170.0
knob_step_deg = 180.0
[acquisition]
samples = 8192
impacts_per_step = 2
[repetitions]
count = 2
"""


def test_path_inverse_removes_the_setup_share() -> None:
    k = np.array([2e7, 4.7e7, 1e8])
    assert roller_stiffness_from_path(roller_path_stiffness(k, K_SETUP), K_SETUP) == pytest.approx(k, rel=1e-12)
    assert np.isnan(roller_stiffness_from_path(K_SETUP / 2, K_SETUP))  # stiffer than the setup: nothing left


def _points(rng: np.random.Generator, sd_load: float, sd_disp: float) -> tuple[list[StaticPoint], np.ndarray]:
    """A roller with k = 3e6·P^0.3 N/m (δ = c·P^0.7) in series with the setup share, read with noise."""
    load = 38.0 + 40.0 * np.arange(10)
    c = 1.0 / (3e6 * 0.7)
    disp = c * load**0.7 + 3.0 * load / K_SETUP
    truth = 3e6 * load**0.3
    pts = [StaticPoint(i + 1, float(p + rng.normal(0, sd_load)), sd_load * np.sqrt(5),
                       float(d + rng.normal(0, sd_disp)), sd_disp * np.sqrt(5), 5, 15.0 * i)
           for i, (p, d) in enumerate(zip(load, disp, strict=True))]
    return pts, truth


def test_static_stiffness_recovers_the_roller_and_its_sigma_covers() -> None:
    rng = np.random.default_rng(7)
    z = []
    for _ in range(150):
        pts, truth = _points(rng, 0.05, 4e-9)
        got = static_stiffness(pts, K_SETUP)
        k = np.array([g.stiffness_n_per_m for g in got])
        z.append((k - truth) / np.array([g.std_n_per_m for g in got]))
        assert set(got[0].budget_n_per_m) == {"load", "displacement", "drift", "shape", "setup_stiffness"}
    z = np.abs(np.array(z))
    # the σ covers at least at its stated rate, and is not grossly inflated: the shape term (parabola vs power law
    # through the same noisy readings) makes it conservative on noise alone (about 89 % within 1 σ here)
    assert 0.68 < np.mean(z < 1) < 0.95 and np.mean(z < 2) > 0.95
    noiseless, truth = _points(rng, 1e-9, 1e-15)
    exact = [g.stiffness_n_per_m for g in static_stiffness(noiseless, K_SETUP)]
    assert exact == pytest.approx(truth, rel=2e-3)  # a power law is the local shape: no bias without noise


def test_static_stiffness_refuses_what_gives_no_slope() -> None:
    pts, _ = _points(np.random.default_rng(1), 0.0, 0.0)
    with pytest.raises(ModelDomainError, match="at least 3"):
        static_stiffness(pts[:2], K_SETUP)
    flat = [dataclasses.replace(p, displacement_m=1e-3 - 1e-7 * p.step) for p in pts]
    with pytest.raises(ModelDomainError, match="does not rise"):
        static_stiffness(flat, K_SETUP)


def test_protocol_static_table() -> None:
    p = parse_protocol(SMALL + "[static]\nreads = 4\ndrift_nm_per_min = 6.0\n")
    assert p.static is not None and p.static.hammer and p.static.reads == 4
    assert p.static.drift_m_per_s == pytest.approx(1e-10)
    assert parse_protocol(SMALL).static is None
    with pytest.raises(InputError, match="static.*method"):
        parse_protocol(SMALL + "[static]\nmethod = 'laser'\n", "p.toml")
    with pytest.raises(InputError, match="reads"):
        parse_protocol(SMALL + "[static]\nreads = 1\n", "p.toml")
    assert load_protocol(ROOT / "protocols" / "static_combined.toml").static is not None


def test_twin_sensor_reads_the_path_deflection_with_its_noise() -> None:
    proto = parse_protocol(SMALL)
    rig = make_rig("sim", case=proto.specimens[0].case(), seed=3)
    sensor = rig.displacement
    assert isinstance(sensor, SimDisplacementSensor)
    quiet = SimDisplacementSensor(sensor.twin, roller_path_stiffness,
                                  DisplacementSettings(noise_m=0.0, resolution_m=0.0, drift_std_m_per_s=0.0))
    twin = sensor.twin
    p0 = twin.preload_n
    twin.set_load_per_roller(p0 + 100.0)
    a = quiet.read()
    twin.set_load_per_roller(p0 + 101.0)
    slope = (quiet.read() - a) / 1.0
    k = np.array(twin.roller_stiffness_n_per_m())
    assert slope == pytest.approx(np.mean(1.0 / roller_path_stiffness(k, twin.rig.setup_stiffness_n_per_m)), rel=2e-3)
    reads = np.array([sensor.read() for _ in range(40)])
    s = sensor.settings
    expected = s.noise_m / np.sqrt(s.window_s * s.sample_rate_hz)
    assert np.std(reads, ddof=1) == pytest.approx(expected, rel=0.35)
    twin.unplug(sensor.name)
    with pytest.raises(DeviceDisconnected):
        sensor.read()


@pytest.fixture(scope="module")
def combined(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("static") / "c.h5"
    proto = parse_protocol(SMALL + "[static]\n", "small_static.toml")
    assert run_campaign(proto, out=out, seed=5).status == "complete"
    return out


def test_combined_campaign_stores_static_curves_that_agree(combined: Path) -> None:
    (c,) = compare(combined)
    assert c.static_n_per_m.shape == c.hammer_n_per_m.shape == (c.step.size, 2) and c.step.size >= 4
    assert np.all(np.isfinite(c.static_n_per_m)) and np.all(c.static_std_n_per_m > 0)
    assert np.max(np.abs(c.z)) < 3.0


def test_report_includes_the_static_figure(combined: Path, tmp_path: Path) -> None:
    from labctl.report import build_report

    res = build_report(combined, tmp_path / "rep")
    assert "fig08_static_vs_hammer" in [f["name"] for f in res.figures]


def test_static_protocol_needs_a_sensor(tmp_path: Path) -> None:
    from drivers.interfaces import Rig
    from labctl.engine.sequencer import Engine
    from labctl.physics import load_rig
    from labctl.storage.memory import MemoryStore

    proto = parse_protocol(SMALL + "[static]\n")

    def factory(spec, index) -> Rig:  # type: ignore[no-untyped-def]
        rig = make_rig("sim", case=spec.case(), seed=1)
        rig.displacement = None
        return rig

    outcome = Engine(proto, load_rig(None), factory, MemoryStore()).run()
    assert outcome.status == "failed" and "no displacement sensor" in outcome.message


def test_static_only_campaign_takes_no_impacts(tmp_path: Path) -> None:
    from labctl.storage.reader import CampaignReader

    out = tmp_path / "s.h5"
    proto = parse_protocol(SMALL + "[static]\nmethod = 'static'\n", "static_only.toml")
    assert run_campaign(proto, out=out, seed=2).status == "complete"
    (c,) = compare(out)
    assert np.all(np.isnan(c.hammer_n_per_m)) and np.all(np.isfinite(c.static_n_per_m))
    with CampaignReader(out) as reader:
        steps = [st for run in reader.runs(1) for st in run.steps]
        assert steps and all(st.complete and not st.impacts for st in steps)
    from labctl.report.static_figure import static_figure

    assert static_figure([c], simulated=True).axes  # the figure draws the static method alone


@pytest.mark.slow
def test_acceptance_static_combined_on_the_twin(tmp_path: Path) -> None:
    """Issue #29: the shipped combined protocol (type 1, Ra 0.2, 3 repetitions): the methods agree at every step
    and repetition (|Δ| < 2 σ of the difference) and the static spread over the upper half of the loads is at
    least twice the hammer's — from the sensor's noise and drift and the load noise in the slope."""
    out = tmp_path / "c.h5"
    assert run_campaign(ROOT / "protocols" / "static_combined.toml", out=out, seed=1).status == "complete"
    (c,) = compare(out)
    assert c.hammer_n_per_m.shape[1] == 3 and c.step.size >= 10
    assert np.max(np.abs(c.z)) < 2.0
    assert c.upper_half_ratio() >= 2.0


def test_resumed_campaign_keeps_the_static_readings(tmp_path: Path) -> None:
    from labctl import events as ev
    from labctl.engine import RunControl
    from labctl.storage.reader import CampaignReader

    proto = tmp_path / "p.toml"
    proto.write_text(SMALL + "[static]\n", encoding="utf-8")
    out, control = tmp_path / "c.h5", RunControl()

    def stop_after_step_2(event: ev.Event) -> None:
        if isinstance(event, ev.StepProcessed) and event.position.step == 2:
            control.stop()

    assert run_campaign(proto, out=out, seed=4, control=control, subscribers=[stop_after_step_2]).status != "complete"
    with CampaignReader(out) as reader:
        before = {st.step: st.attrs["static_displacement_m"] for st in reader.runs(1)[0].steps}
    assert run_campaign(proto, out=out, resume=True).status == "complete"
    (c,) = compare(out)
    assert np.all(np.isfinite(c.static_n_per_m))
    with CampaignReader(out) as reader:
        after = {st.step: st.attrs["static_displacement_m"] for st in reader.runs(1)[0].steps}
    assert {k: after[k] for k in before} == before
