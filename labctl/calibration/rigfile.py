"""Write a calibrated rig file: the nominal file's text with the fitted values, [uncertainty] and [calibration]."""

from __future__ import annotations

import json
import math
import re
from typing import Any

from labctl.calibration.fit import FitResult
from labctl.errors import InputError
from labctl.physics.rig_config import rig_from_text

# fitted parameter -> the rig file's (table, key) that hold it
LOCATIONS: dict[str, tuple[tuple[str, str], ...]] = {
    "mass_kg": (("upper_disc", "mass_kg"), ("lower_disc", "mass_kg")),
    "inertia_kg_m2": (("upper_disc", "inertia_kg_m2"), ("lower_disc", "inertia_kg_m2")),
    "setup_stiffness_n_per_m": (("contacts", "setup_stiffness_n_per_m"),),
    "support_stiffness_n_per_m": (("support", "stiffness_n_per_m"),),
}
REPLACED_TABLES = ("uncertainty", "calibration")
_HEADER = re.compile(r"^\s*\[\[?\s*([A-Za-z0-9_.\-]+)\s*\]\]?")
_KEY = re.compile(r"^(\s*)([A-Za-z0-9_\-]+)(\s*=\s*)([^#]*?)(\s*(#.*)?)$")


def toml_value(value: Any) -> str:
    """A TOML literal for a number, string, bool or list of them (JSON strings are valid TOML basic strings)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"cannot write {value!r} to a rig file")
        return repr(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    return json.dumps(str(value), ensure_ascii=False)


def calibrated_rig_text(nominal_text: str, source: str, fit: FitResult, provenance: dict[str, Any]) -> str:
    """The nominal rig file with the determined parameters replaced and the calibration's uncertainty table.

    Everything else (sensors, loading, flexible modes, comments) is copied, so ``rig_from_text`` reads it back.
    """
    targets = {loc: fit.values[p] for p in fit.free for loc in LOCATIONS[p]}
    out: list[str] = []
    table = ""
    skipping = False
    done: set[tuple[str, str]] = set()
    for line in nominal_text.splitlines():
        header = _HEADER.match(line)
        if header:
            table = header.group(1)
            skipping = table.split(".")[0] in REPLACED_TABLES
        if skipping:
            continue
        key = _KEY.match(line) if not header else None
        if key and (table, key.group(2)) in targets:
            loc = (table, key.group(2))
            line = f"{key.group(1)}{key.group(2)}{key.group(3)}{toml_value(targets[loc])}{key.group(5)}"
            done.add(loc)
        out.append(line)
    missing = sorted(set(targets) - done)
    if missing:
        raise InputError(f"{source}: cannot write the calibrated values: no line "
                         f"{', '.join(f'[{t}] {k} = …' for t, k in missing)} in the nominal rig file")
    corr = fit.correlation.get("mass_kg", {}).get("setup_stiffness_n_per_m", 0.0)
    uncertainty = {"mass_std_kg": fit.total_std["mass_kg"],
                   "setup_stiffness_std_n_per_m": fit.total_std["setup_stiffness_n_per_m"],
                   "mass_setup_correlation": max(-1.0, min(1.0, corr)),
                   "model_rel": provenance.pop("model_rel", 0.0)}
    out += ["", "[uncertainty]  # 1-σ from the calibration fit (labctl calibrate)"]
    out += [f"{k} = {toml_value(float(v))}" for k, v in uncertainty.items()]
    out += ["", "[calibration]  # provenance: how and from what this rig description was calibrated"]
    out += [f"{k} = {toml_value(v)}" for k, v in provenance.items()]
    text = "\n".join(out) + "\n"
    check = rig_from_text(text, source)
    for p in fit.free:
        got = {"mass_kg": check.upper.mass_kg, "inertia_kg_m2": check.upper.inertia_kg_m2,
               "setup_stiffness_n_per_m": check.setup_stiffness_n_per_m,
               "support_stiffness_n_per_m": check.support_stiffness_n_per_m}[p]
        if not math.isclose(got, fit.values[p], rel_tol=1e-12):
            raise InputError(f"{source}: the calibrated {p} did not read back ({got!r} ≠ {fit.values[p]!r})")
    return text
