"""Test protocol files shipped with labctl (importable as ``labctl.protocols`` for resource lookup)."""
