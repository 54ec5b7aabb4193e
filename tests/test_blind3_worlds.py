"""The third blind judge's worlds: valid stiffness tables, a null that scatters around Tripp, determinism."""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path

import numpy as np
import pytest

from bench.blind3 import laws
from bench.blind3.contact import load_catalogue, tripp_k
from bench.blind3.worlds import COLUMNS, SCENARIOS, generate, main

ROLLERS, MATERIALS = load_catalogue()
REQUIRED = ("diameter_mm", "contact_length_mm", "rail_ra_um", "load_n", "stiffness_n_per_m")
LABELS = {"surface_roughness", "end_effects", "material_hardness", "misalignment", "setup_compliance",
          "outside_library"}


def _residual(rows: list[dict]) -> np.ndarray:
    """ln(measured k / Tripp at the reported load) per row."""
    out = []
    for r in rows:
        ro = ROLLERS[r["roller_type"]]
        k = tripp_k(np.array([r["load_n"]]), ro, MATERIALS[r["material"]], MATERIALS[r["rail_material"]])[0]
        out.append(np.log(r["stiffness_n_per_m"] / k))
    return np.array(out)


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_every_scenario_is_a_valid_table(scenario: str) -> None:
    """Contract columns only, required ones present, positive load and stiffness, truth labels in the brief's set."""
    for seed in (0, 1):
        t0 = time.perf_counter()
        ds = generate(scenario, seed, 1.0)
        assert time.perf_counter() - t0 < 0.5
        assert ds.rows
        for r in ds.rows:
            assert set(REQUIRED) <= set(r) <= set(COLUMNS)
            assert r["load_n"] > 0 and r["stiffness_n_per_m"] > 0 and r["repetition"] >= 1
            assert r.get("stiffness_std_n_per_m", 0.0) >= 0
        tr = ds.truth
        assert set(tr["effects"]) <= LABELS and set(tr["measurement_effects"]) <= set(laws.MEASUREMENT)
        assert tr["outside_library"] == ("outside_library" in tr["effects"])
        assert set(tr["family"]) == set(tr["effects"]) | set(tr["measurement_effects"])
        assert 3 <= len(tr["design"]["units"]) <= 7
        for u in tr["design"]["units"]:
            assert 2 <= u["repetitions"] <= 4 and 6 <= u["steps"] <= 14
        if scenario.startswith("null"):
            assert tr["size_sigma"] == 0.0 and not tr["effects"]


def test_null_scatters_around_tripp_within_the_noise() -> None:
    """A null world's residual to Tripp has a mean within the noise and a spread of the stated σ's order."""
    for seed in range(4):
        ds = generate("null", seed, 1.0)
        res = _residual(ds.rows)
        sig = ds.truth["noise"]["median_sigma_rel"]
        assert abs(res.mean()) < 1.5 * sig
        assert 0.4 * sig < res.std() < 2.5 * sig


def test_deterministic_and_same_world_across_noise_scales() -> None:
    """Same seed: same rows; across noise scales the same design and effects, the noise scaled in proportion."""
    a, b = generate("pair_physical_measurement", 3, 1.0), generate("pair_physical_measurement", 3, 1.0)
    assert a.rows == b.rows and json.dumps(a.truth, sort_keys=True) == json.dumps(b.truth, sort_keys=True)
    worlds = {s: generate("null", 2, s) for s in (0.5, 1.0, 2.0)}
    keys = ("design", "family", "params", "faults")
    for s in (0.5, 2.0):
        assert all(worlds[s].truth[k] == worlds[1.0].truth[k] for k in keys)
        assert [r["roller_type"] for r in worlds[s].rows] == [r["roller_type"] for r in worlds[1.0].rows]
    r1, r2 = _residual(worlds[1.0].rows), _residual(worlds[2.0].rows)
    assert np.corrcoef(r1, r2)[0, 1] > 0.98 and 1.8 < r2.std() / r1.std() < 2.2
    eff = {s: generate("roughness", 5, s).truth for s in (0.5, 1.0, 2.0)}
    assert eff[0.5]["params"] == eff[2.0]["params"]
    assert eff[0.5]["size_sigma"] == pytest.approx(4 * eff[2.0]["size_sigma"], rel=1e-2)


def test_cli_writes_csv_and_truth(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The CLI writes SCENARIO_sSEED_nNOISE.csv and .truth.json and prints the summary."""
    main(["--out", str(tmp_path), "--seeds", "1", "--noise", "1", "--summary"])
    files = sorted(tmp_path.glob("*.csv"))
    assert len(files) == len(SCENARIOS)
    with open(tmp_path / "null_s0_n1.csv", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert set(REQUIRED) <= set(rows[0])
    assert json.loads((tmp_path / "null_s0_n1.truth.json").read_text())["scenario"] == "null"
    assert "share ≥3σ" in capsys.readouterr().out


def test_baseline_is_labctl_tripp() -> None:
    """The judge's Tripp equals labctl's TrippContact (the baseline the lab believes)."""
    from labctl.physics import TrippContact, material, roller

    for t in (1, 2, 4, 8, 9):
        r = ROLLERS[t]
        loads = np.array([30.0, 300.0, 3000.0])
        ref = TrippContact(roller(t), material("1.3505")).stiffness_n_per_m(loads)
        assert np.allclose(tripp_k(loads, r, MATERIALS[r.material], MATERIALS["1.3505"]), ref, rtol=1e-12)


def test_every_family_gives_a_finite_positive_stiffness() -> None:
    """Each family at the geometric middle of its amplitude range yields finite positive k on short and long rollers."""
    from bench.blind3.model import Unit, rig_processing, roller_k, unit_law

    rng = np.random.default_rng(0)
    units = [Unit(0, ROLLERS[2], MATERIALS["1.3505"], MATERIALS["1.3505"], 0.2),
             Unit(1, ROLLERS[4], MATERIALS["1.3505"], MATERIALS["1.3505"], 0.03)]
    loads, rep = np.array([30.0, 100.0, 1000.0]), np.array([1, 2, 3])
    for label, fams in laws.FAMILIES.items():
        for fam in fams:
            prm = laws.draw_params(fam, rng, [3, 3], 1000.0)
            prm["amp"] = float(np.sqrt(np.prod(laws.AMP_RANGE[fam])))
            prm["material"] = "1.3505"
            eff = {label: (fam, prm)}
            for u in units:
                k = rig_processing(roller_k(u, unit_law(u, eff), eff, loads, rep), loads, eff)
                assert np.all(np.isfinite(k)) and np.all(k > 0), (label, fam)
