"""HDF5 campaign files: written one impact at a time (``writer``), read back for processing and reports."""

from __future__ import annotations

from labctl.storage.reader import CampaignReader, RunInfo, StepInfo
from labctl.storage.table import campaign_stiffness_points
from labctl.storage.writer import CampaignWriter, ImpactData

__all__ = ["CampaignReader", "CampaignWriter", "ImpactData", "RunInfo", "StepInfo", "campaign_stiffness_points"]
