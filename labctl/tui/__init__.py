"""The terminal UI for the technician at the rig (Textual): live run with dialogs, and a campaign-file browser."""

from __future__ import annotations

from labctl.tui.app import DEFAULT_AUTO_CONFIRM_S, LabApp, TuiSettings

__all__ = ["DEFAULT_AUTO_CONFIRM_S", "LabApp", "TuiSettings"]
