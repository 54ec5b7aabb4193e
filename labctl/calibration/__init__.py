"""Rig calibration from ball runs: disc mass, K_setup (and what else the data determine) with Hertz contacts."""

from __future__ import annotations

from labctl.calibration.data import BallStep, CampaignBalls, read_ball_steps
from labctl.calibration.fit import (
    PARAMETERS,
    FitResult,
    expected_rel_std,
    fit_rig,
    predict_hz,
    rig_values,
    rig_with,
)

__all__ = ["PARAMETERS", "BallStep", "CampaignBalls", "FitResult", "expected_rel_std", "fit_rig", "predict_hz",
           "read_ball_steps", "rig_values", "rig_with"]
