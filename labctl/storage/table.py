"""The stiffness table of a campaign file: one StiffnessPoint per identified step of every repetition."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from labctl.stiffness_table import (
    BUDGET_COLUMNS,
    FLAG_CHANNELS,
    FLAG_LOAD_DRIFT,
    FLAG_OVERRIDE,
    StiffnessPoint,
)
from labctl.storage.reader import CampaignReader, StepInfo
from labctl.storage.records import OPERATOR, StepResult


def step_flags(step: StepInfo, result: StepResult | None = None) -> tuple[float | None, str | None]:
    """The load read after a step's blows and what happened at it, as the stiffness table's optional columns."""
    r = result if result is not None else step.result
    flags = [FLAG_LOAD_DRIFT] if step.load_drift else []
    if r is not None and (r.dead_channels or r.dropped_channels):
        flags.append(FLAG_CHANNELS)
    if any(i.verdict.source == OPERATOR and i.verdict.accepted != i.checks.accepted for i in step.impacts):
        flags.append(FLAG_OVERRIDE)
    after = step.load_after_n
    return (after if math.isfinite(after) else None), (";".join(flags) or None)


def specimen_point(specimen: dict[str, Any], repetition: int, load_n: float, stiffness_n_per_m: float,
                   result: StepResult | None = None, step: StepInfo | None = None) -> StiffnessPoint:
    """A table row for a measured point of a stored specimen (with the result's uncertainty budget when given,
    and with ``step`` the load after its blows and what happened at it)."""
    after, flags = step_flags(step, result) if step is not None else (None, None)
    rt = specimen.get("roller_type")
    budget = result.roller_stiffness_budget_n_per_m if result is not None else {}
    std = result.roller_stiffness_std_n_per_m if result is not None else None
    return StiffnessPoint(
        diameter_m=float(specimen["diameter_m"]), contact_length_m=float(specimen["contact_length_m"]),
        rail_ra_m=float(specimen["rail_ra_m"]), load_n=float(load_n), stiffness_n_per_m=float(stiffness_n_per_m),
        roller_type=None if rt is None or rt == "" else int(rt),
        roller_length_m=float(specimen["roller_length_m"]) if "roller_length_m" in specimen else None,
        material=specimen.get("material"), youngs_modulus_pa=specimen.get("youngs_modulus_pa"),
        poisson_ratio=specimen.get("poisson_ratio"), hardness_hrc=specimen.get("hardness_hrc"),
        repetition=int(repetition), rail_material=specimen.get("rail_material") or None,
        stiffness_std_n_per_m=std if std is not None and math.isfinite(std) else None,
        load_after_n=after, flags=flags,
        **{column: float(budget[key]) for key, column in BUDGET_COLUMNS.items() if key in budget})


def campaign_stiffness_points(path: str | Path) -> list[StiffnessPoint]:
    """Points from the stored step results (run ``labctl process`` to recompute them from raw impacts)."""
    points: list[StiffnessPoint] = []
    with CampaignReader(path) as reader:
        for series in reader.series_indices():
            spec = reader.specimen(series)
            for run in reader.runs(series):
                for step in run.steps:
                    if step.result is not None and step.result.identified:
                        points.append(specimen_point(spec, run.run, step.load_n,
                                                     step.result.roller_stiffness_n_per_m, step.result, step))
    return points
