"""The archive's one contact with campaign files and their processing.

Everything the archive needs from ``labctl.storage.CampaignReader`` and ``labctl.reprocess.process_campaign`` is
read here into plain records, so a change of those interfaces is adapted in this module alone.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from labctl.data import data_path
from labctl.physics.rig_config import DEFAULT_RIG
from labctl.reprocess import process_campaign, rig_of
from labctl.stiffness_table import StiffnessPoint
from labctl.storage import CampaignReader, result_summary
from labctl.storage.results import attrs_sha256
from labctl.storage.specimen import SpecimenRecord


@dataclass(frozen=True)
class StepRecord:
    """One load step as stored: its attributes, impact counts and the identification made at acquisition."""

    series: int
    run: int
    step: int
    run_complete: bool
    step_complete: bool
    attrs: dict[str, Any]
    result: dict[str, Any] | None
    impacts: int
    accepted_impacts: int


@dataclass(frozen=True)
class CampaignRecord:
    """What the catalogue keeps of one campaign file (no raw impacts)."""

    path: str
    attrs: dict[str, Any]
    root_sha256: str
    protocol_text: str | None
    rig_text: str | None
    specimens: dict[int, SpecimenRecord]
    steps: list[StepRecord] = field(default_factory=list)


@dataclass(frozen=True)
class RigUsed:
    """The rig description a reprocessing used: where it came from, its name and a hash of its text."""

    source: str
    name: str
    sha256: str


@dataclass(frozen=True)
class Reprocessed:
    """Every step of a campaign identified again from its raw impacts (as ``labctl process`` does)."""

    path: str
    status: str
    size_bytes: int
    root_sha256: str
    rig: RigUsed
    steps: list[dict[str, Any]]
    points: list[StiffnessPoint]


def root_sha256(path: str | Path) -> str:
    """Hash of a campaign's root attributes (opens the file, reads no data, so skips the structure walk)."""
    with CampaignReader(path, attrs_only=True) as reader:
        return attrs_sha256(reader.attrs)


def read_campaign(path: str | Path) -> CampaignRecord:
    """Root attributes, stored configuration, specimens and every step's stored result of a campaign file."""
    with CampaignReader(path) as reader:
        attrs = reader.attrs
        specimens = {series: reader.specimen(series) for series in reader.series_indices()}
        steps = [StepRecord(st.series, run.run, st.step, run.complete, st.complete, st.attrs,
                            result_summary(st.result) if st.result and st.result.identified else None,
                            len(st.impacts), st.accepted_count)
                 for series in specimens for run in reader.runs(series) for st in run.steps]
        return CampaignRecord(str(path), attrs, attrs_sha256(attrs), reader.config_text("protocol.toml"),
                              reader.config_text("rig.toml"), specimens, steps)


def _rig_used(reader: CampaignReader) -> RigUsed:
    text = reader.config_text("rig.toml")
    source = "campaign:/config/rig.toml"
    if text is None:
        text, source = data_path(DEFAULT_RIG).read_text(encoding="utf-8"), f"shipped:{DEFAULT_RIG}"
    return RigUsed(source, rig_of(reader).name, hashlib.sha256(text.encode()).hexdigest())


def reprocess(path: str | Path) -> Reprocessed:
    """Identify every step again with the current processing code and the campaign's stored rig."""
    done = process_campaign(path)
    with CampaignReader(path) as reader:
        rig, root = _rig_used(reader), attrs_sha256(reader.attrs)
    steps = [{"series": r.series, "specimen": r.specimen, "run": r.run, "step": r.step, "load_n": r.load_n,
              "knob_angle_deg": r.knob_angle_deg,
              "result": result_summary(r.result) if r.result.identified else None, "error": r.error} for r in done.rows]
    return Reprocessed(str(path), done.status, Path(path).stat().st_size, root, rig, steps, list(done.points))
