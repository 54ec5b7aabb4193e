"""Names and versions of the campaign file layout (documented in docs/storage.md)."""

from __future__ import annotations

FORMAT = "labctl-campaign"
FORMAT_VERSION = 1
CONFIG = "config"
FORCE = "force_n"
ACCEL = "accel_m_per_s2"
RESULT = "result"
CURVE = "curve"
COMPLETE = "complete"
FRF_MAX_HZ = 2500.0


def series_name(series: int) -> str:
    return f"series_{series:02d}"


def run_name(run: int) -> str:
    return f"run_{run:02d}"


def step_name(step: int) -> str:
    return f"step_{step:03d}"


def impact_name(attempt: int) -> str:
    return f"impact_{attempt:03d}"


def index_of(name: str) -> int:
    """The 1-based number at the end of a group name (``step_007`` → 7)."""
    return int(name.rsplit("_", 1)[1])
