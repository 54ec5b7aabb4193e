"""The terminal UI for the technician at the rig (Textual): live run with dialogs, and a campaign-file browser."""

from __future__ import annotations

import os

FRAME_RATE_HZ = 20
"""Most screen updates per second (Textual's default is 60): the screen changes with each blow, a countdown's second
or a key, and the PC that draws it is also the one acquiring. ``TEXTUAL_FPS`` in the environment overrides it."""
os.environ.setdefault("TEXTUAL_FPS", str(FRAME_RATE_HZ))  # read once, when Textual is first imported (just below)

from labctl.tui.app import DEFAULT_AUTO_CONFIRM_S, LabApp, TuiSettings  # noqa: E402

__all__ = ["DEFAULT_AUTO_CONFIRM_S", "FRAME_RATE_HZ", "LabApp", "TuiSettings"]
