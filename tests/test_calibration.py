"""Rig calibration from ball runs: the twin hides a heavier disc and a softer setup; calibrate must find them.

One small simulated campaign per ball size (module fixture) and one roller campaign on the same hidden rig
serve every end-to-end test; the fit's own properties are checked on synthetic ball steps from the rig model.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from labctl.calibration import BallStep, expected_rel_std, fit_rig, read_ball_steps, rig_values
from labctl.calibration.calibrate import Calibration
from labctl.calibration.fit import rig_with
from labctl.calibration.rigfile import calibrated_rig_text
from labctl.campaign import run_campaign
from labctl.errors import InputError
from labctl.physics import HertzBallContact, load_rig, material, rig_modes
from labctl.physics.rig_config import rig_from_text
from labctl.physics.world import load_world
from labctl.protocol import load_protocol
from tests.cli_util import assert_one_line_error, labctl_here

NOMINAL = load_rig()
TRUE_MASS_KG = 1.02 * NOMINAL.upper.mass_kg
TRUE_SETUP_N_PER_M = 0.75 * NOMINAL.setup_stiffness_n_per_m
# The rig is what is tested here: the blows' contact nonlinearity is switched off so a step's truth is the law's.
HIDDEN_RIG = f"""
[instruments]
contact_nonlinearity = 0.0
[rig.upper_disc]
mass_kg = {TRUE_MASS_KG!r}
[rig.lower_disc]
mass_kg = {TRUE_MASS_KG!r}
[rig.contacts]
setup_stiffness_n_per_m = {TRUE_SETUP_N_PER_M!r}
"""
SMALL = """
[acquisition]
samples = 16384
impacts_per_step = 2
"""
STEEL = material("1.3505")


def _ball_protocol(diameter_mm: float, max_load_n: float, count: int) -> str:
    return f"""[protocol]
name = "calibration_{diameter_mm:g}mm"
version = 1
[[specimens]]
kind = "ball"
ball_diameter_mm = {diameter_mm}
rail_ra_um = 0.03
max_load_n = {max_load_n}
knob_step_deg = 360.0
{SMALL}
[repetitions]
count = {count}
"""


@pytest.fixture(scope="module")
def twin(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Ball campaigns of 6 and 9 mm and a roller campaign on a rig 2 % heavier and 25 % softer than its file."""
    d = tmp_path_factory.mktemp("calibration")
    balls_world = d / "balls_hidden_rig.toml"
    balls_world.write_text('[baseline]\nmodel = "hertz"\n[scatter]\nstiffness_rel = 0.003\n' + HIDDEN_RIG)
    roller_world = d / "rollers_hidden_rig.toml"
    roller_world.write_text('[baseline]\nmodel = "tripp"\ndepth_mm = 1.5\n' + HIDDEN_RIG)
    out = {"balls_world": balls_world, "roller_world": roller_world}
    for name, (diam, load, seed) in {"b6": (6.0, 200.0, 1), "b9": (9.0, 440.0, 2)}.items():
        proto = d / f"{name}.toml"
        proto.write_text(_ball_protocol(diam, load, 2))
        out[name] = d / f"{name}.h5"
        assert run_campaign(proto, out=out[name], world=balls_world, seed=seed).status == "complete"
    proto = d / "roller.toml"
    proto.write_text('[protocol]\nname = "roller"\nversion = 1\n[specimen]\nkind = "roller"\nroller_type = 1\n'
                     'rail_ra_um = 0.2\nmax_load_n = 220.0\nknob_step_deg = 360.0\n' + SMALL
                     + "[repetitions]\ncount = 1\n")
    out["roller_protocol"] = proto
    out["roller"] = d / "roller.h5"
    assert run_campaign(proto, out=out["roller"], world=roller_world, seed=3).status == "complete"
    return out


@pytest.fixture(scope="module")
def calibrated(twin: dict[str, Path]) -> tuple[dict, Path]:
    from labctl.cli import main

    rig_out = twin["b6"].parent / "calibrated_rig.toml"
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["calibrate", str(twin["b6"]), str(twin["b9"]), "--out", str(rig_out), "--json"]) == 0
    return json.loads(buf.getvalue()), rig_out


def test_hidden_mass_and_setup_stiffness_recovered_within_their_stated_2_sigma(calibrated):
    r, _ = calibrated
    mass_err = r["mass_kg"] - TRUE_MASS_KG
    k_err = r["setup_stiffness_n_per_m"] - TRUE_SETUP_N_PER_M
    assert abs(mass_err) / TRUE_MASS_KG < 0.005
    assert abs(mass_err) < 2 * r["mass_std_kg"]
    assert abs(k_err) / TRUE_SETUP_N_PER_M < 0.10
    assert abs(k_err) < 2 * r["setup_stiffness_std_n_per_m"]
    # the nominal values are far outside what the fit allows
    assert abs(r["mass_kg"] - NOMINAL.upper.mass_kg) > 5 * r["mass_std_kg"]
    assert abs(r["setup_stiffness_n_per_m"] - NOMINAL.setup_stiffness_n_per_m) > 5 * r["setup_stiffness_std_n_per_m"]
    assert -1 <= r["mass_setup_correlation"] <= 1 and r["mass_setup_correlation"] > 0.5  # both raise the bounce
    assert r["ball_sizes_mm"] == [6.0, 9.0]
    assert r["fit"]["dof"] > 0 and r["fit"]["chi2"] == pytest.approx(r["fit"]["dof"], rel=0.5)
    assert r["warnings"] == []
    assert any("upper vs lower disc mass" in c for c in r["cannot_separate"])


def test_calibrated_rig_file_reads_back_with_uncertainty_and_provenance(calibrated):
    r, rig_out = calibrated
    rig = load_rig(rig_out)
    assert rig.upper.mass_kg == rig.lower.mass_kg == pytest.approx(r["mass_kg"], rel=1e-12)
    assert rig.setup_stiffness_n_per_m == pytest.approx(r["setup_stiffness_n_per_m"], rel=1e-12)
    assert rig.uncertainty.mass_std_kg == pytest.approx(r["mass_std_kg"])
    assert rig.uncertainty.setup_stiffness_std_n_per_m == pytest.approx(r["setup_stiffness_std_n_per_m"])
    assert rig.uncertainty.mass_setup_correlation == pytest.approx(r["mass_setup_correlation"])
    assert rig.uncertainty.model_rel == NOMINAL.uncertainty.model_rel
    assert rig.calibration["determined"][:2] == ["mass_kg", "setup_stiffness_n_per_m"]
    assert len(rig.calibration["campaigns"]) == 2
    # everything not calibrated is the nominal rig's
    assert rig.sensors == NOMINAL.sensors and rig.flexible_modes == NOMINAL.flexible_modes
    if r["support_stiffness_n_per_m"] is None:
        assert rig.support_stiffness_n_per_m == NOMINAL.support_stiffness_n_per_m


def test_roller_stiffness_with_the_calibrated_rig_matches_the_world(twin, calibrated, capsys):
    _, rig_out = calibrated
    world = load_world(twin["roller_world"])
    case = load_protocol(twin["roller_protocol"]).specimens[0].case()
    errors = {}
    for label, extra in (("nominal", []), ("calibrated", ["--rig", str(rig_out)])):
        proc = labctl_here(capsys, "process", str(twin["roller"]), *extra, "--json")
        assert proc.returncode == 0, proc.stderr
        steps = json.loads(proc.stdout)["steps"]
        assert len(steps) == 3
        errors[label] = [s["roller_stiffness_n_per_m"] / float(world.law.stiffness_n_per_m(case, s["load_n"])) - 1
                         for s in steps]
    assert max(abs(e) for e in errors["calibrated"]) < 0.003
    assert min(abs(e) for e in errors["nominal"]) > 0.003


def test_one_ball_size_says_what_it_cannot_separate(twin, capsys, tmp_path):
    out = tmp_path / "one_size.toml"
    proc = labctl_here(capsys, "calibrate", str(twin["b9"]), "--out", str(out), "--json")
    assert proc.returncode == 0, proc.stderr
    r = json.loads(proc.stdout)
    assert r["setup_stiffness_n_per_m"] is None and r["setup_stiffness_std_n_per_m"] is None
    assert r["mass_setup_correlation"] is None
    why = {e["parameter"]: e["why"] for e in r["not_determined"]}
    assert "one ball size (9 mm)" in why["setup_stiffness_n_per_m"]
    assert any(c.startswith("setup_stiffness_n_per_m: one ball size") for c in r["cannot_separate"])
    # the mass is still determined, with K_setup free in the fit: its error stays inside its stated 2σ
    assert abs(r["mass_kg"] - TRUE_MASS_KG) < 2 * r["mass_std_kg"]
    rig = load_rig(out)  # K_setup stays nominal, with the nominal uncertainty
    assert rig.setup_stiffness_n_per_m == NOMINAL.setup_stiffness_n_per_m
    assert rig.uncertainty.setup_stiffness_std_n_per_m == pytest.approx(NOMINAL.uncertainty.setup_stiffness_std_n_per_m)
    assert rig.uncertainty.mass_setup_correlation == 0.0
    text = labctl_here(capsys, "calibrate", str(twin["b9"])).stdout
    assert "K_setup            not determined" in text and "one ball size (9 mm)" in text


def test_campaign_without_balls_is_a_one_line_error(twin, capsys):
    proc = labctl_here(capsys, "calibrate", str(twin["roller"]))
    assert_one_line_error(proc, str(twin["roller"]), "no identified ball steps")


# --- the world's [rig] table -------------------------------------------------------------------------------

def test_world_rig_table_sets_the_true_rig_and_composes_with_setup_compliance(twin, tmp_path):
    world = load_world(twin["balls_world"])
    true = world.true_rig(NOMINAL)
    assert true.upper.mass_kg == true.lower.mass_kg == TRUE_MASS_KG
    assert true.setup_stiffness_n_per_m == TRUE_SETUP_N_PER_M
    assert true.upper.inertia_kg_m2 == NOMINAL.upper.inertia_kg_m2
    p = tmp_path / "w.toml"
    p.write_text('[baseline]\nmodel = "tripp"\n[effects.setup_compliance]\nstiffness_factor = 2.0\n'
                 '[rig.contacts]\nsetup_stiffness_n_per_m = 1e9\nradius_mm = 80.0\n'
                 '[rig.support]\nstiffness_n_per_m = 4e5\n')
    true = load_world(p).true_rig(NOMINAL)
    assert true.setup_stiffness_n_per_m == 2e9
    assert true.contact_radius_m == pytest.approx(0.080)
    assert true.support_stiffness_n_per_m == 4e5


@pytest.mark.parametrize(("table", "message"), [
    ("[rig.upper]\nmass_kg = 11.0\n",
     "rig: unknown key(s) upper (did you mean 'upper_disc'?); expected one of contacts, damping"),
    ("[rig.upper_disc]\nmass = 11.0\n",
     "rig.upper_disc: unknown key(s) mass (did you mean 'mass_kg'?); expected one of inertia_kg_m2, mass_kg"),
    ("[rig.contacts]\nsetup_stiffness_n_per_m = -1.0\n",
     "rig.contacts.setup_stiffness_n_per_m = -1.0: expected a positive number"),
    ("[rig]\nupper_disc = 3\n", "rig.upper_disc = 3: expected a table"),
])
def test_world_rig_table_errors_name_table_and_key(tmp_path, table, message):
    p = tmp_path / "bad.toml"
    p.write_text('[baseline]\nmodel = "hertz"\n' + table)
    with pytest.raises(InputError, match=None) as exc:
        load_world(p)
    assert str(p) in str(exc.value) and message in str(exc.value)


# --- the fit on synthetic ball steps from the rig model ----------------------------------------------------

def synthetic_steps(rig, design, *, seed=0, seating_rel=0.0, load_noise_n=0.0, std_hz=2e-4):
    """Ball steps as the rig model (``rig``) produces them: per seating one stiffness factor per ball."""
    rng = np.random.default_rng(seed)
    steps = []
    for diameter_mm, loads, runs in design:
        contact = HertzBallContact(diameter_mm * 1e-3, STEEL, STEEL)
        for run in range(runs):
            factors = np.exp(seating_rel * rng.standard_normal(3))
            for f in loads:
                modes = rig_modes(rig, factors * float(contact.stiffness_n_per_m(f)))
                read = f + load_noise_n * rng.standard_normal(2)
                steps.append(BallStep(f"synthetic {diameter_mm} mm run {run} {f} N", f"{diameter_mm}:{run}",
                                      float(read[0]), float(read[1]), contact,
                                      modes.bounce_hz + std_hz * rng.standard_normal(), std_hz,
                                      float(np.mean(modes.tilt_hz)), 10 * std_hz))
    return steps


LOADS = [38.0, 77.0, 116.0, 155.0, 194.0, 233.0, 272.0, 311.0, 350.0, 389.0, 428.0]


def test_fit_recovers_the_model_exactly_from_noise_free_steps():
    truth = rig_with(NOMINAL, {"mass_kg": 11.9, "setup_stiffness_n_per_m": 1.2e9, "inertia_kg_m2": 0.058})
    steps = synthetic_steps(truth, [(6.0, LOADS[:6], 1), (9.0, LOADS, 1)], std_hz=1e-6)
    fit = fit_rig(NOMINAL, steps)
    assert fit.values["mass_kg"] == pytest.approx(11.9, rel=1e-5)
    assert fit.values["setup_stiffness_n_per_m"] == pytest.approx(1.2e9, rel=1e-3)
    assert fit.values["inertia_kg_m2"] == pytest.approx(0.058, rel=1e-5)


def test_fit_uncertainties_cover_the_truth_at_their_stated_rate():
    truth = rig_with(NOMINAL, {"mass_kg": 11.7, "setup_stiffness_n_per_m": 1.3e9})
    z = []
    for seed in range(4):
        steps = synthetic_steps(truth, [(6.0, LOADS[:5:2], 2), (9.0, LOADS[::2], 2)], seed=seed,
                                seating_rel=0.003, load_noise_n=0.1)
        fit = fit_rig(NOMINAL, steps)
        for p, v in rig_values(truth).items():
            if p in ("mass_kg", "setup_stiffness_n_per_m"):
                z.append((fit.values[p] - v) / fit.std[p])
    z = np.abs(np.array(z))
    assert np.all(z < 3.5), z
    assert np.mean(z < 2) >= 0.75, z


def test_inconsistent_data_are_flagged_not_trusted():
    a = synthetic_steps(NOMINAL, [(6.0, LOADS[:5:2], 2)], seed=1)
    b = synthetic_steps(rig_with(NOMINAL, {"mass_kg": 14.0}), [(9.0, LOADS[::4], 2)], seed=2)
    fit = fit_rig(NOMINAL, a + b, use_tilt=False)
    cal = Calibration(fit, NOMINAL, Path(NOMINAL.source).read_text(), ["a", "b"], a + b)
    assert fit.seating_scatter_rel > 0.03
    assert cal.warnings() and "do not use this calibration" in cal.warnings()[0]


def test_one_seating_per_ball_size_is_flagged():
    steps = synthetic_steps(NOMINAL, [(6.0, LOADS[:5:2], 1), (9.0, LOADS[::4], 1)], seed=3, seating_rel=0.003)
    fit = fit_rig(NOMINAL, steps, use_tilt=False)
    warnings = Calibration(fit, NOMINAL, "", ["a"], steps).warnings()
    assert any("6 mm, 9 mm seated only once" in w for w in warnings), warnings


def test_calibration_protocol_determines_mass_and_setup_stiffness():
    """The shipped protocol's balls and loads fix mass to < 0.2 % and K_setup to < 3 % (seating scatter 0.3 %)."""
    proto = load_protocol(Path(__file__).resolve().parents[1] / "protocols" / "calibration.toml")
    design = []
    per_step = NOMINAL.load_per_knob_degree_n
    for spec in proto.specimens:
        assert spec.kind == "ball"
        loads = list(np.arange(NOMINAL.preload_per_roller_n, spec.max_load_n, spec.knob_step_deg * per_step))
        design.append((spec.ball_diameter_m * 1e3, loads, proto.repetitions.count))
    assert len({d for d, _, _ in design}) >= 2
    steps = synthetic_steps(NOMINAL, design)
    rel = expected_rel_std(NOMINAL, steps, seating_rel=0.003 / math.sqrt(3), load_noise_n=0.1)
    assert rel["mass_kg"] < 0.002 and rel["setup_stiffness_n_per_m"] < 0.03
    # one ball size alone would fix K_setup only through the load dependence, and worse
    one = expected_rel_std(NOMINAL, [s for s in steps if s.ball_diameter_m > 0.008], seating_rel=0.003 / math.sqrt(3),
                           load_noise_n=0.1)
    assert one["setup_stiffness_n_per_m"] > rel["setup_stiffness_n_per_m"]


def test_rig_writer_refuses_a_rig_file_without_the_calibrated_keys():
    steps = synthetic_steps(NOMINAL, [(6.0, LOADS[:5], 1), (9.0, LOADS, 1)])
    fit = fit_rig(NOMINAL, steps)
    text = Path(NOMINAL.source).read_text()
    written = rig_from_text(calibrated_rig_text(text, "x.toml", fit, {"model_rel": 0.003}), "x.toml")
    assert written.calibration == {} and math.isclose(written.upper.mass_kg, fit.values["mass_kg"])
    broken = text.replace("[upper_disc]\nmass_kg = 11.6", '[upper_disc]\n"mass_kg" = 11.6')  # valid, but quoted
    assert broken != text
    with pytest.raises(InputError, match="upper_disc"):
        calibrated_rig_text(broken, "x.toml", fit, {})


def test_read_ball_steps_uses_stored_results_loads_and_ball_attributes(twin):
    c = read_ball_steps(twin["b9"])
    assert c.rig_text and not c.skipped
    assert {round(s.ball_diameter_m, 9) for s in c.steps} == {0.009}
    assert len({s.run_key for s in c.steps}) == 2
    assert all(s.bounce_hz > 0 and s.tilt_hz and s.load_repeat_n for s in c.steps)


def test_identify_with_the_calibrated_rig_matches_the_world(twin, calibrated, capsys, tmp_path):
    _, rig_out = calibrated
    npz = tmp_path / "impacts.npz"
    proc = labctl_here(capsys, "simulate", "impacts", "--roller-type", "1", "--load-n", "200", "--impacts", "2",
                       "--world", str(twin["roller_world"]), "--seed", "3", "--out", str(npz), "--json")
    assert proc.returncode == 0, proc.stderr
    truth = json.loads(proc.stdout)["roller_stiffness_n_per_m"][0]
    got = {}
    for label, extra in (("nominal", []), ("calibrated", ["--rig", str(rig_out)])):
        proc = labctl_here(capsys, "identify", str(npz), *extra, "--json")
        assert proc.returncode == 0, proc.stderr
        got[label] = json.loads(proc.stdout)["roller_stiffness_n_per_m"] / truth - 1
    assert abs(got["calibrated"]) < 0.003 < abs(got["nominal"])


def test_a_campaign_run_with_the_calibrated_rig_stores_it_with_its_provenance(twin, calibrated, capsys, tmp_path):
    r, rig_out = calibrated
    proto = tmp_path / "one_step.toml"
    proto.write_text(_ball_protocol(9.0, 45.0, 1))  # the preload step only
    out = tmp_path / "with_calibrated_rig.h5"
    proc = labctl_here(capsys, "run", str(proto), "--world", str(twin["balls_world"]), "--rig", str(rig_out),
                       "--seed", "9", "--out", str(out), "--json")
    assert proc.returncode == 0, proc.stderr
    stored = read_ball_steps(out).rig_text
    rig = rig_from_text(stored, "stored")
    assert rig.upper.mass_kg == pytest.approx(r["mass_kg"], rel=1e-12)
    assert rig.calibration["campaigns"] == [str(twin["b6"]), str(twin["b9"])]
    # campaigns of different stored rigs need the nominal rig named
    proc = labctl_here(capsys, "calibrate", str(twin["b6"]), str(out))
    assert_one_line_error(proc, str(out), "different rig description", "--rig")
