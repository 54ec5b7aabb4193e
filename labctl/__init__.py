"""labctl: acquisition, sequencing and analysis of hammer-impact tests of roller-rail contact stiffness."""

from __future__ import annotations

__version__ = "0.1.0"
