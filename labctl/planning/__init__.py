"""Planning the next measurement: which specimen and which loads would teach the most about the candidate
effects the discrepancy workflow still weighs, and when no further measurement would change its verdict."""

from __future__ import annotations

from labctl.planning.plan import Plan, Recommendation, parse_candidates, plan_from_result, plan_measurements

__all__ = ["Plan", "Recommendation", "parse_candidates", "plan_from_result", "plan_measurements"]
