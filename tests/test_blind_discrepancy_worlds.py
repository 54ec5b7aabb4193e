"""The blind discrepancy worlds (bench/blind): valid stiffness tables, a null that scatters around Tripp within
its stated noise, effects with the load and geometry signature they claim, and a truthful `size_sigma`."""

from __future__ import annotations

import csv
import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

BLIND = Path(__file__).resolve().parents[1] / "bench" / "blind"
sys.path.insert(0, str(BLIND))
import blind_contact as bc  # noqa: E402
import blind_families as bf  # noqa: E402

# a unique module name: bench/ holds another discrepancy_worlds.py that other tests may import by that name
_spec = importlib.util.spec_from_file_location("blind_discrepancy_worlds", BLIND / "discrepancy_worlds.py")
dw = importlib.util.module_from_spec(_spec)
sys.modules["blind_discrepancy_worlds"] = dw  # dataclasses resolve their module by name
_spec.loader.exec_module(dw)

from labctl.physics import TrippContact, material, roller  # noqa: E402

REQUIRED = ("diameter_mm", "contact_length_mm", "rail_ra_um", "load_n", "stiffness_n_per_m")
SPECS = bc.load_rollers()
RAIL = bc.load_materials()[bc.RAIL_MATERIAL]


def _tripp(row: dict) -> float:
    s = SPECS[row["roller_type"]]
    return float(bc.tripp_stiffness(np.array([row["load_n"]]), s.contact_length_m, s.radius_m, s.material, RAIL)[0])


def _ratio_by_type(ds: dw.BlindDataset) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """(loads, ln k/k_tripp) per roller type, noise included."""
    out: dict[int, list] = {}
    for r in ds.rows:
        out.setdefault(r["roller_type"], []).append((r["load_n"], np.log(r["stiffness_n_per_m"] / _tripp(r))))
    return {t: (np.array([a for a, _ in v]), np.array([b for _, b in v])) for t, v in out.items()}


def test_own_tripp_matches_the_library_baseline():
    for t in dw.ROLLER_TYPES:
        s = SPECS[t]
        loads = np.linspace(38.0, 0.31 * bc.static_rating_n(s, RAIL), 11)
        mine = bc.tripp_stiffness(loads, s.contact_length_m, s.radius_m, s.material, RAIL)
        lib = TrippContact(roller(t), material(bc.RAIL_MATERIAL)).stiffness_n_per_m(loads)
        np.testing.assert_allclose(mine, lib, rtol=1e-10)
    assert 1e-9 * bc.effective_modulus_pa(RAIL, RAIL) == pytest.approx(114.6, abs=0.05)


@pytest.mark.parametrize("scenario", dw.SCENARIOS)
def test_each_scenario_gives_a_valid_table(scenario):
    ds = dw.generate(scenario, seed=3, noise_scale=1.0)
    extra = 0 if ds.truth["faults"]["duplicate_row"] is None else 1
    assert len(ds.rows) == 231 + extra
    for r in ds.rows:
        assert set(REQUIRED) <= set(r) and set(r) <= set(dw.COLUMNS)
        assert r["stiffness_n_per_m"] > 0 and np.isfinite(r["stiffness_n_per_m"])
        assert r["load_n"] > 0 and r["stiffness_std_n_per_m"] > 0
        assert r["rail_ra_um"] in (0.2, 0.03) and r["repetition"] in (1, 2, 3)
    types = {r["roller_type"] for r in ds.rows}
    assert types == set(dw.ROLLER_TYPES)
    truth = ds.truth
    assert set(truth["effects"]) <= {*dw.PHYSICAL, "outside_library"}
    assert set(truth["measurement_effects"]) <= set(dw.CALIBRATION)
    assert truth["outside_library"] == scenario.startswith("outside_")
    assert set(truth["family"]) == set(truth["effects"])
    assert (truth["size_sigma"] == 0.0) == (scenario == "none")
    json.dumps(truth)  # the truth is plain JSON


def test_deterministic_per_seed_and_different_across_seeds():
    a, b = dw.generate("surface_roughness", 5, 1.0), dw.generate("surface_roughness", 5, 1.0)
    assert a.rows == b.rows and a.truth == b.truth
    assert dw.generate("surface_roughness", 6, 1.0).rows != a.rows


def test_null_scatters_around_tripp_within_its_stated_noise():
    """ln(k/k_tripp)/σ_rel of the null world is ~N(0, 1): the stated σ covers the scatter, no bias."""
    for noise in (0.5, 2.0):
        z = []
        for seed in range(4):
            ds = dw.generate("none", seed, noise)
            bad = ds.truth["faults"]["outliers"]
            for r in ds.rows:
                if bad and r["roller_type"] == bad["roller_type"]:
                    continue
                z.append(np.log(r["stiffness_n_per_m"] / _tripp(r)) * r["stiffness_n_per_m"] / r[
                    "stiffness_std_n_per_m"])
        z = np.array(z)
        assert 0.85 < z.std() < 1.15
        assert abs(z.mean()) < 0.25  # seating shifts are shared by 11 points: the mean is noisier than 1/sqrt(n)
        assert np.mean(np.abs(z) < 1.0) == pytest.approx(0.683, abs=0.06)


def test_noise_scale_changes_the_noise_not_the_world():
    lo, hi = dw.generate("end_effects", 2, 0.5), dw.generate("end_effects", 2, 2.0)
    assert lo.truth["params"] == hi.truth["params"]
    assert hi.truth["size_sigma"] == pytest.approx(lo.truth["size_sigma"] / 4.0, rel=1e-9)
    # the same draws scaled: the difference of the two tables is 3x the low-noise noise (2.0 - 0.5 = 1.5 x scale 1)
    diff = np.array([np.log(b["stiffness_n_per_m"] / a["stiffness_n_per_m"]) for a, b in zip(lo.rows, hi.rows,
                                                                                              strict=True)])
    assert [a["load_n"] for a in lo.rows] == [b["load_n"] for b in hi.rows]
    sigma1 = lo.truth["median_sigma_rel"] / 0.5
    assert np.std(diff) == pytest.approx(1.5 * sigma1, rel=0.35)


@pytest.mark.parametrize("family", [f.name for f in dw.PHYSICAL["surface_roughness"]])
def test_roughness_softens_light_loads_and_rough_rails_most(family):
    """Noise-free (scale 1e-6): every roller loses most at light load, and more on Ra 0.2 than on Ra 0.03."""
    ds = dw.generate("surface_roughness", 3, 1e-6, families={"surface_roughness": family})
    for loads, ln in _ratio_by_type(ds).values():
        order = np.argsort(loads)
        assert ln[order[0]] < ln[order[-1]] <= 1e-5
    params = dict(ds.truth["params"]["surface_roughness"])
    amp = params.pop("amp")
    fam = next(f for f in dw.PHYSICAL["surface_roughness"] if f.name == family)
    loads = np.linspace(38.0, 450.0, 11)
    ln = {ra: np.log(fam.apply(bf.RollerLoads(SPECS[1], RAIL, ra, loads), params, amp)
                     / bc.tripp_stiffness(loads, SPECS[1].contact_length_m, SPECS[1].radius_m, RAIL, RAIL))
          for ra in (0.2, 0.03)}
    assert np.all(ln[0.2] < ln[0.03]) and np.all(ln[0.03] < 0)


def test_lost_length_hits_short_rollers_hardest():
    ds = dw.generate("end_effects", 4, 0.5, families={"end_effects": "lost_length"})
    mean_ln = {t: ln.mean() for t, (_, ln) in _ratio_by_type(ds).items()}
    assert mean_ln[2] < mean_ln[4] < 0  # 1.1 mm loses more of its length than 8.3 mm


def test_wedge_misalignment_closes_with_load():
    ds = dw.generate("misalignment", 0, 0.5, families={"misalignment": "wedge"})
    loads, ln = _ratio_by_type(ds)[4]  # the longest roller opens the widest gap
    assert ln[loads == loads.min()].mean() < ln[loads == loads.max()].mean()
    assert abs(ln[loads > np.percentile(loads, 80)].mean()) < 0.05


def test_load_gain_is_tripp_at_the_true_load():
    ds = dw.generate("load_gain", 0, 1.0)
    gain = ds.truth["params"]["load_gain"]["gain"]
    z = []
    for r in ds.rows:
        true = {**r, "load_n": r["load_n"] / gain}
        z.append(np.log(r["stiffness_n_per_m"] / _tripp(true)) * r["stiffness_n_per_m"] / r["stiffness_std_n_per_m"])
    assert abs(np.median(z)) < 0.3


def test_size_sigma_matches_the_clean_departure_and_spans_three_sigma():
    sizes = [dw.generate(s, seed, 1.0).truth["size_sigma"]
             for s in ("surface_roughness", "end_effects", "material_hardness", "setup_compliance")
             for seed in range(6)]
    share = np.mean(np.array(sizes) >= 3.0)
    assert 0.5 < share < 1.0  # most effects are >= 3 σ, some are smaller
    for scenario in (*dw.CALIBRATION, "end_effects"):  # one component: the total is that component's size
        truth = dw.generate(scenario, 1, 1.0).truth
        assert truth["size_sigma"] == pytest.approx(truth["size_sigma_by_effect"][scenario], rel=1e-6)
    ds = dw.generate("setup_compliance", 0, 1.0)
    observed = np.concatenate([ln for _, ln in _ratio_by_type(ds).values()])
    # the largest noisy departure is the clean one give or take a few point σ
    assert np.max(np.abs(observed)) / ds.truth["median_sigma_rel"] == pytest.approx(ds.truth["size_sigma"], abs=4.0)


def test_cli_writes_tables_and_truths(tmp_path):
    assert dw.main(["--out", str(tmp_path), "--seeds", "1", "--noise", "1", "--scenarios", "none", "load_offset"]) == 0
    with (tmp_path / "load_offset_0_1.csv").open(encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) >= 231 and set(REQUIRED) <= set(rows[0])
    truth = json.loads((tmp_path / "load_offset_0_1.json").read_text(encoding="utf-8"))
    assert truth["measurement_effects"] == ["load_offset"]
    assert 5 <= abs(truth["params"]["load_offset"]["offset_n"]) <= 25
    assert dw.main(["--out", str(tmp_path), "--seeds", "0"]) == 2
