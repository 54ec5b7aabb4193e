"""Input screening before any fit: duplicated rows, conflicting duplicates and implausible units.

A fully duplicated row (or file) would double its weight; two rows for the same roller, repetition and load
with different stiffness cannot both be right; a stiffness a thousand times below any contact model's is a
unit slip (N/mm given as N/m), not physics. Each finding is reported; units are refused with a hint.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from labctl.discrepancy.data import Dataset
from labctl.errors import InputError
from labctl.physics.tripp import DEFAULT_DEPTH_M, TrippContact
from labctl.stiffness_table import StiffnessPoint

UNIT_TOLERANCE = 30.0
"""Median measured/Tripp ratio outside [1/30, 30] is refused as a unit error."""
UNIT_HINTS = ((1e-3, "N/mm (1 N/mm = 1000 N/m)"), (1e-6, "N/µm (1 N/µm = 1e6 N/m)"), (1e3, "N/km or mN/m"),
              (1e-2, "N/cm"))


@dataclass
class Screening:
    """What the screen found (rows are 1-based positions in the pooled input)."""

    duplicates: list[dict[str, Any]] = field(default_factory=list)
    conflicting_rows: list[dict[str, Any]] = field(default_factory=list)
    outliers: list[dict[str, Any]] = field(default_factory=list)
    drifted: list[dict[str, Any]] = field(default_factory=list)
    """Points measured while the load drifted (flag ``load_drift``): set aside, their load is not known."""
    end_steps: list[dict[str, Any]] = field(default_factory=list)
    """A seating's first or last step that every repetition leaves the same way while every other step follows the
    fit: kept (a tilt bedding in, a yield setting in, would look the same), but the misfit is that step's alone."""

    def to_dict(self) -> dict[str, Any]:
        return {"duplicates": self.duplicates, "conflicting_rows": self.conflicting_rows, "outliers": self.outliers,
                "drifted": self.drifted, "end_steps": self.end_steps}

    def note_end_step(self, data: Dataset, indices: Sequence[int], end: str, residuals: np.ndarray,
                      against: str) -> None:
        """Record the end step at ``indices`` (``end``: "first" or "last" of its case's loads; ``residuals`` =
        ln(k_model/k_measured) of the fit it departs from, ``against`` that fit's name), once per case and step."""
        case = data.case_of(int(indices[0]))
        loads = sorted(float(data.load_n[k]) for k in indices)
        note = {"case": data.cases[case].label, "step": end, "load_n": loads, "against": against,
                "off_rel": float(np.median(np.expm1(-residuals[list(indices)])))}
        if not any(n["case"] == note["case"] and n["load_n"] == loads for n in self.end_steps):
            self.end_steps.append(note)

    @property
    def any(self) -> bool:
        return bool(self.duplicates or self.conflicting_rows or self.outliers or self.drifted)

    def set_aside(self, data: Dataset, indices: Sequence[int]) -> Dataset:
        """Report the points at ``indices`` as outliers and return the dataset without them."""
        mask = np.zeros(data.n_points, dtype=bool)
        mask[list(indices)] = True
        labels = [(c, i) for c in data.cases for i in range(c.load_n.size)]
        for k in indices:
            c, i = labels[k]
            self.outliers.append({"case": c.label, "repetition": int(c.repetition[i]), "load_n": float(c.load_n[i]),
                                  "stiffness_n_per_m": float(np.exp(c.ln_stiffness[i]))})
        return data.drop_points(mask)


def _key(p: StiffnessPoint) -> tuple[Any, ...]:
    return (p.diameter_m, p.contact_length_m, p.rail_ra_m, p.roller_type, p.roller_length_m, p.material,
            p.rail_material, p.youngs_modulus_pa, p.poisson_ratio, p.hardness_hrc, p.repetition, p.load_n)


def screen_points(points: Sequence[StiffnessPoint]) -> tuple[list[StiffnessPoint], Screening]:
    """Drop exact duplicates, set aside points whose load drifted during their step (the stiffness belongs to
    a load between ``load_n`` and ``load_after_n``) and, of rows that claim the same roller, repetition and load
    with different stiffness, keep the one nearest the other repetitions at that load."""
    found = Screening()
    seen: dict[StiffnessPoint, int] = {}
    unique: list[tuple[int, StiffnessPoint]] = []
    for i, p in enumerate(points, 1):
        if p.drifted:
            found.drifted.append({"row": i, "repetition": p.repetition, "load_n": p.load_n,
                                  "load_after_n": p.load_after_n, "stiffness_n_per_m": p.stiffness_n_per_m})
            continue
        if p in seen:
            found.duplicates.append({"row": i, "same_as_row": seen[p], "load_n": p.load_n,
                                     "stiffness_n_per_m": p.stiffness_n_per_m})
            continue
        seen[p] = i
        unique.append((i, p))
    by_key: dict[tuple[Any, ...], list[tuple[int, StiffnessPoint]]] = {}
    for i, p in unique:
        if p.repetition is not None:
            by_key.setdefault(_key(p), []).append((i, p))
    drop: set[int] = set()
    for rows in by_key.values():
        if len(rows) < 2:
            continue
        p0 = rows[0][1]
        others = [q.stiffness_n_per_m for _, q in unique
                  if _key(q)[:10] == _key(p0)[:10] and q.repetition != p0.repetition
                  and abs(q.load_n / p0.load_n - 1.0) <= 0.05]
        ref = float(np.median(np.log(others))) if others else math.log(rows[0][1].stiffness_n_per_m)
        keep = min(rows, key=lambda r: abs(math.log(r[1].stiffness_n_per_m) - ref))
        for i, p in rows:
            if i != keep[0]:
                drop.add(i)
                found.conflicting_rows.append({"row": i, "kept_row": keep[0], "repetition": p.repetition,
                                               "load_n": p.load_n, "stiffness_n_per_m": p.stiffness_n_per_m,
                                               "kept_stiffness_n_per_m": keep[1].stiffness_n_per_m})
    return [p for i, p in unique if i not in drop], found


def check_units(data: Dataset) -> None:
    """Refuse stiffness values that no contact model of these rollers comes near (a unit slip), with a hint."""
    ratios = np.concatenate([
        c.ln_stiffness - np.log(TrippContact(c.case.roller, c.case.rail, DEFAULT_DEPTH_M).stiffness_n_per_m(c.load_n))
        for c in data.cases])
    median = float(np.exp(np.median(ratios)))
    if 1.0 / UNIT_TOLERANCE <= median <= UNIT_TOLERANCE:
        return
    hint = min(UNIT_HINTS, key=lambda h: abs(math.log(median / h[0])))
    looks = f"; the values look like {hint[1]}" if abs(math.log(median / hint[0])) < math.log(10) else ""
    raise InputError(f"stiffness_n_per_m: measured values are {median:.3g} × a Tripp estimate for these rollers "
                     f"(median over {data.n_points} points), far outside any plausible contact{looks}; "
                     "give roller stiffness in N/m")
