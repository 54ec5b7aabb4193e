"""The processing's one error type: raised when an impact set leaves nothing that can be identified."""

from __future__ import annotations

from labctl.errors import LabctlError


class ProcessingError(LabctlError):
    """No usable result: every impact rejected, no mode found, or data the pipeline cannot read."""
