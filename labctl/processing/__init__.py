"""Modal processing of hammer impacts: checks, FRF, contact-mode identification and roller stiffness."""

from __future__ import annotations

from labctl.processing.checks import REASONS, CheckConfig, ImpactCheck, check_impact
from labctl.processing.errors import ProcessingError
from labctl.processing.frf import WindowConfig
from labctl.processing.identification import Identification, IdentifyConfig, Mode
from labctl.processing.identify import identify
from labctl.processing.npz import ImpactSet, load_impacts_npz

__all__ = [
    "REASONS", "CheckConfig", "Identification", "IdentifyConfig", "ImpactCheck", "ImpactSet", "Mode",
    "ProcessingError", "WindowConfig", "check_impact", "identify", "load_impacts_npz",
]
