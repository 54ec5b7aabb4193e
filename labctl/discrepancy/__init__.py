"""Discrepancy workflow: where measured stiffness and the model disagree, which effect is missing, how much
of the gap it closes."""

from __future__ import annotations

from labctl.discrepancy.data import Dataset, build_dataset, load_points
from labctl.discrepancy.workflow import DiscrepancyResult, run_discrepancy, run_files

__all__ = ["Dataset", "DiscrepancyResult", "build_dataset", "load_points", "run_discrepancy", "run_files"]
