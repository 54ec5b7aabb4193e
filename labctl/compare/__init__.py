"""Is a stiffness-vs-load difference between two groups of campaigns significant? (``labctl compare``)."""

from labctl.compare.groups import Curve, load_group
from labctl.compare.test import Comparison, LoadDifference, compare_groups

__all__ = ["Comparison", "Curve", "LoadDifference", "compare_groups", "load_group"]
