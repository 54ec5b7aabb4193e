"""(Re)process a campaign file from its raw impacts with the current processing code."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from labctl.physics.rig_config import RigConfig, load_rig, rig_from_text
from labctl.processing import CheckConfig, ProcessingError, identify
from labctl.protocol import parse_protocol
from labctl.stiffness_table import StiffnessPoint
from labctl.storage import CampaignReader
from labctl.storage.table import specimen_point


@dataclass
class StepRow:
    series: int
    specimen: str
    run: int
    step: int
    load_n: float
    knob_angle_deg: float
    result: dict[str, Any] | None
    error: str = ""


@dataclass
class Processed:
    path: str
    status: str
    rows: list[StepRow] = field(default_factory=list)
    points: list[StiffnessPoint] = field(default_factory=list)


def rig_of(reader: CampaignReader) -> RigConfig:
    """The rig description stored in the campaign (falls back to the shipped default)."""
    text = reader.config_text("rig.toml")
    return rig_from_text(text, f"{reader.path}:/config/rig.toml") if text else load_rig()


def process_campaign(path: str | Path, rig: RigConfig | str | Path | None = None) -> Processed:
    """Identify every step of every run again from its stored impacts (with ``rig``: another rig description)."""
    with CampaignReader(path) as reader:
        rig = rig_of(reader) if rig is None else rig if isinstance(rig, RigConfig) else load_rig(rig)
        proto_text = reader.config_text("protocol.toml")
        config = parse_protocol(proto_text, f"{path}:/config/protocol.toml").checks if proto_text else CheckConfig()
        out = Processed(str(path), str(reader.attrs.get("status", "")))
        for series in reader.series_indices():
            spec = reader.specimen(series)
            for run in reader.runs(series):
                for step in run.steps:
                    row = StepRow(series, str(spec.get("label", "")), run.run, step.step, step.load_n,
                                  float(step.attrs.get("knob_angle_deg", 0.0)), None)
                    data = reader.impact_arrays(series, run.run, step.step)
                    if not data.attempts:
                        row.error = "no impacts stored"
                    else:
                        try:
                            ident = identify(data.force_n, data.accel_m_per_s2, data.sample_rate_hz, data.channels,
                                             rig, accel_ranges=data.accel_ranges, force_range_n=data.force_range_n,
                                             config=config)
                            row.result = ident.to_dict()
                            out.points.append(specimen_point(spec, run.run, step.load_n,
                                                             ident.roller_stiffness_n_per_m))
                        except ProcessingError as exc:
                            row.error = str(exc)
                    out.rows.append(row)
    return out


