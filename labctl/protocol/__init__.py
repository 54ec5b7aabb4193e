"""Test protocols: TOML files describing specimens, loading, acquisition and repetitions, validated on load."""

from __future__ import annotations

from labctl.protocol.model import (
    AcquisitionSpec,
    LoadingSpec,
    Protocol,
    RepetitionSpec,
    SpecimenSpec,
)
from labctl.protocol.parse import load_protocol, parse_protocol, resolve_protocol_path, shipped_protocols

__all__ = [
    "AcquisitionSpec", "LoadingSpec", "Protocol", "RepetitionSpec", "SpecimenSpec", "load_protocol",
    "parse_protocol", "resolve_protocol_path", "shipped_protocols",
]
