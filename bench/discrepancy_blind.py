"""The blind judges of the discrepancy workflow (``bench/blind/``, ``bench/blind2/``): loading a judge, its truth
as the workflow names explanations, its rows through the CSV contract, and how much of a world Tripp's depth
cannot absorb. Used by ``bench/discrepancy_eval.py``."""

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
CALIBRATION_SEEDS = 100_000
"""The blind worlds' seeds from here on calibrate the temperature; evaluation seeds stay below it."""
_MODULES: dict[str, Any] = {}


def blind_worlds(suite: str = "blind") -> Any:
    """The blind generator of ``suite`` (``blind`` or ``blind2``), imported under its own name (its siblings on
    the path)."""
    if suite in _MODULES:
        return _MODULES[suite]
    where, file = (BLIND2_DIR, "worlds.py") if suite == "blind2" else (BLIND_DIR, "discrepancy_worlds.py")
    for folder in (where, where.parents[1]):  # blind2 imports its siblings as ``bench.blind2.*``
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
