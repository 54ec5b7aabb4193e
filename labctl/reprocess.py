"""(Re)process a campaign file from its stored impacts with the current processing code and the same step
pipeline the engine uses (stored verdicts honoured)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from labctl.errors import InputError
from labctl.physics.rig_config import RigConfig, load_rig, rig_from_text
from labctl.processing import CheckConfig
from labctl.protocol import parse_protocol
from labctl.recording import process_step
from labctl.stiffness_table import StiffnessPoint
from labctl.storage import CampaignReader, LogEntry, StepInfo, StepResult


@dataclass
class StepRow:
    series: int
    specimen: str
    run: int
    step: int
    load_n: float
    knob_angle_deg: float
    result: StepResult
    info: StepInfo | None = None  # the stored step: loads before and after, impacts and their verdicts

    @property
    def error(self) -> str:
        return self.result.error


@dataclass
class Processed:
    path: str
    status: str
    rows: list[StepRow] = field(default_factory=list)
    points: list[StiffnessPoint] = field(default_factory=list)
    log: list[LogEntry] = field(default_factory=list)  # the run log as stored (retries, suspends, prompts, ...)


def rig_of(reader: CampaignReader) -> RigConfig:
    """The rig description stored in the campaign (InputError when the file has none), with the stored devices
    file's per-channel accelerometer cross-axis values when it gives any."""
    rig = rig_from_text(reader.required_config("rig.toml"), f"{reader.path}:/config/rig.toml")
    devices = reader.config_text("devices.toml")
    if not devices:
        return rig
    from labctl.hardware import rig_with_channel_cross_axis

    return rig_with_channel_cross_axis(rig, devices, f"{reader.path}:/config/devices.toml")


def checks_of(reader: CampaignReader) -> CheckConfig:
    """The impact checks the campaign ran with (an import without a protocol: the defaults)."""
    text = reader.config_text("protocol.toml")
    return parse_protocol(text, f"{reader.path}:/config/protocol.toml").checks if text else CheckConfig()


def process_campaign(path: str | Path, rig: RigConfig | str | Path | None = None) -> Processed:
    """Identify every step of every run again from its stored impacts (with ``rig``: another rig description)."""
    with CampaignReader(path) as reader:
        rig = rig_of(reader) if rig is None else rig if isinstance(rig, RigConfig) else load_rig(rig)
        checks = checks_of(reader)
        if reader.step_count() == 0:
            raise InputError(f"{path}: the campaign holds no load step yet (nothing was measured)")
        out = Processed(str(path), str(reader.attrs.get("status", "")), log=reader.log())
        for series in reader.series_indices():
            spec = reader.specimen(series)
            for run in reader.runs(series):
                for step in run.steps:
                    result = process_step(reader.impacts(series, run.run, step.step), rig, checks)
                    out.rows.append(StepRow(series, spec.label, run.run, step.step, step.load_n,
                                            step.knob_angle_deg, result, step))
                    if result.identified:
                        out.points.append(spec.point(run.run, step.load_n, result.roller_stiffness_n_per_m, result,
                                                     step=step))
    return out
