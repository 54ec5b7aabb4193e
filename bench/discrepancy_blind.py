"""The blind judges of the discrepancy workflow (``bench/blind/``, ``bench/blind2/``, ``bench/blind3/``): loading a
judge, its truth as the workflow names explanations, its rows through the CSV contract, and how much of a world
Tripp's depth cannot absorb. Used by ``bench/discrepancy_eval.py``."""

from __future__ import annotations

import csv
import importlib.util
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from labctl.discrepancy import build_dataset, load_points
from labctl.discrepancy.measurement import MEASUREMENT
from labctl.discrepancy.model import ModelSpec, fit_model
from labctl.physics import EFFECTS

BLIND_DIR = Path(__file__).resolve().parent / "blind"
"""Worlds written blind to the workflow (their brief: ``bench/blind/discrepancy_brief.md``)."""
BLIND2_DIR = Path(__file__).resolve().parent / "blind2"
"""A second judge written blind to the workflow and to the first (``bench/blind2/brief.md``): never tuned on."""
BLIND3_DIR = Path(__file__).resolve().parent / "blind3"
"""A third, blind to the workflow and to both (``bench/blind3/brief.md``): it varies the campaign's structure
(types, repetitions, uneven steps) and the noise (drift, load-cell noise, a stated σ too small); never tuned on."""
JUDGES: dict[str, tuple[Path, str, str]] = {
    "blind": (BLIND_DIR, "discrepancy_worlds.py", "bench/blind"),
    "blind2": (BLIND2_DIR, "worlds.py", "second judge, bench/blind2"),
    "blind3": (BLIND3_DIR, "worlds.py", "third judge, bench/blind3")}
"""Each judge's folder, generator file and name in a printout."""
CALIBRATION_SEEDS = 100_000
"""The blind worlds' seeds from here on calibrate the temperature; evaluation seeds stay below it."""
_MODULES: dict[str, Any] = {}


def blind_worlds(suite: str = "blind") -> Any:
    """The blind generator of ``suite`` (a key of ``JUDGES``), imported under its own name (its siblings on the
    path)."""
    if suite in _MODULES:
        return _MODULES[suite]
    where, file, _ = JUDGES[suite]
    for folder in (where, where.parents[1]):  # a judge may import its siblings as ``bench.blindN.*``
        if str(folder) not in sys.path:
            sys.path.insert(0, str(folder))
    spec = importlib.util.spec_from_file_location(f"{suite}_discrepancy_worlds", where / file)
    if spec is None or spec.loader is None or not (where / file).exists():
        raise SystemExit(f"{where / file} missing: merge the blind worlds' branch first")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    _MODULES[suite] = module
    return module


def truth_name(truth: dict[str, Any]) -> str:
    """The blind truth as the workflow names explanations ("unlisted" for an effect outside the library)."""
    if truth.get("outside_library"):
        return "unlisted"
    phys = [n for n in EFFECTS if n in truth.get("effects", [])]
    meas = [n for n in MEASUREMENT if n in truth.get("measurement_effects", [])]
    return " + ".join(phys + meas) or "none"


def csv_points(rows: list[dict[str, Any]]) -> list[Any]:
    """Rows through the CSV contract: written as a stiffness table and read back as the CLI reads it."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "blind.csv"
        columns = list(dict.fromkeys(k for row in rows for k in row))
        with open(path, "w", newline="", encoding="utf-8") as fh:
            writer = csv.DictWriter(fh, columns)
            writer.writeheader()
            writer.writerows(rows)
        return load_points([path])


def visible_size(scenario: str, seed: int, truth: dict[str, Any]) -> float:
    """What Tripp's depth cannot absorb: the largest |ln k/k_Tripp| of the noise-free world (faults left out)
    after the depth is refitted, over the median point σ — the blind truth's ``size_sigma`` is before it."""
    clean = blind_worlds().generate(scenario, seed, 1e-9)
    fault = (truth.get("faults") or {}).get("outliers")
    rows = [r for r in clean.rows if not (fault and int(r["roller_type"]) == fault["roller_type"]
                                          and int(r["repetition"]) in fault["repetitions"])]
    data = build_dataset(csv_points(rows))
    fit = fit_model(data, ModelSpec())
    return float(np.max(np.abs(fit.residuals))) / float(truth["median_sigma_rel"])
