"""HDF5 campaign files: written one impact at a time (``writer``), read back for processing and reports."""

from __future__ import annotations

from labctl.storage.reader import CampaignReader, RunInfo, StepInfo, open_campaign
from labctl.storage.writer import CampaignWriter, ImpactData

__all__ = ["CampaignReader", "CampaignWriter", "ImpactData", "RunInfo", "StepInfo", "campaign_stiffness_points",
           "open_campaign"]


def campaign_stiffness_points(path):  # noqa: ANN001, ANN201 - re-exported from the table module
    """The stiffness table of a campaign file (one point per processed step of every run)."""
    from labctl.storage.table import campaign_stiffness_points as _points

    return _points(path)
