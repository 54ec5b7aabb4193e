"""The stiffness table of a campaign file: one StiffnessPoint per identified step of every repetition."""

from __future__ import annotations

from pathlib import Path

from labctl.stiffness_table import StiffnessPoint
from labctl.storage.reader import CampaignReader


def campaign_stiffness_points(path: str | Path) -> list[StiffnessPoint]:
    """Points from the stored step results (run ``labctl process`` to recompute them from raw impacts)."""
    points: list[StiffnessPoint] = []
    with CampaignReader(path) as reader:
        for series in reader.series_indices():
            spec = reader.specimen(series)
            for run in reader.runs(series):
                for step in run.steps:
                    if step.result is not None and step.result.identified:
                        points.append(spec.point(run.run, step.load_n, step.result.roller_stiffness_n_per_m,
                                                 step.result, step=step))
    return points
