"""The stiffness table of a campaign file: one StiffnessPoint per identified step of every repetition."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from labctl.stiffness_table import StiffnessPoint
from labctl.storage.reader import CampaignReader, RunInfo


def campaign_stiffness_points(path: str | Path) -> list[StiffnessPoint]:
    """Points from the stored step results (run ``labctl process`` to recompute them from raw impacts)."""
    with CampaignReader(path) as reader:
        return stiffness_points(reader)


def stiffness_points(reader: CampaignReader, runs: Mapping[int, list[RunInfo]] | None = None
                     ) -> list[StiffnessPoint]:
    """The open campaign's points; ``runs`` (series → its repetitions) when the caller has read them already."""
    points: list[StiffnessPoint] = []
    for series in reader.series_indices():
        spec = reader.specimen(series)
        for run in runs[series] if runs is not None else reader.runs(series):
            for step in run.steps:
                if step.result is not None and step.result.identified:
                    points.append(spec.point(run.run, step.load_n, step.result.roller_stiffness_n_per_m,
                                             step.result, step=step))
    return points
