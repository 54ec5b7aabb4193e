"""UFF58 interchange (docs/contracts.md): export campaigns, read time records from other acquisition systems, import.

pyuff is imported lazily by the modules that read or write files, so ``import labctl.uff`` stays cheap.
"""

from __future__ import annotations

from labctl.uff.mapping import DEFAULT_NODES, NodeMap, parse_node_map
from labctl.uff.reader import UffFile, UffImpacts, load_impacts_uff, read_uff_impacts, sample_rate_hz

UFF_SUFFIXES = (".uff", ".unv")

__all__ = ["DEFAULT_NODES", "UFF_SUFFIXES", "NodeMap", "UffFile", "UffImpacts", "load_impacts_uff",
           "parse_node_map", "read_uff_impacts", "sample_rate_hz"]
