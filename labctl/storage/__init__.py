"""HDF5 campaign files: typed records written one impact at a time (``writer``), read back (``reader``)."""

from __future__ import annotations

from labctl.storage.reader import CampaignReader, RunInfo, StepInfo
from labctl.storage.records import (
    Calibration,
    CheckSummary,
    ImpactInfo,
    ImpactOutcome,
    ImpactRecord,
    ModeResult,
    RepetitionCurve,
    StepFrf,
    StepResult,
    Verdict,
    result_summary,
)
from labctl.storage.runlog import LogEntry, LogSummary
from labctl.storage.table import campaign_stiffness_points
from labctl.storage.writer import CampaignWriter

__all__ = ["Calibration", "CampaignReader", "CampaignWriter", "CheckSummary", "ImpactInfo", "ImpactOutcome",
           "ImpactRecord", "LogEntry", "LogSummary", "ModeResult", "RepetitionCurve", "RunInfo", "StepFrf",
           "StepInfo", "StepResult", "Verdict", "campaign_stiffness_points", "result_summary"]
