"""Typed instrument errors: each names the device and what it was doing when it failed."""

from __future__ import annotations


class DeviceError(Exception):
    """An instrument failed; ``device`` names it (e.g. ``loadcell@/dev/ttyUSB0``), ``action`` what it was doing."""

    def __init__(self, device: str, action: str, detail: str = "") -> None:
        self.device, self.action, self.detail = device, action, detail
        super().__init__(f"{device}: {action} failed" + (f": {detail}" if detail else ""))


class DeviceTimeout(DeviceError):
    """The instrument did not answer (or the trigger did not come) within the allowed time."""


class DeviceDisconnected(DeviceError):
    """The instrument went away (unplugged, port closed, ENODEV)."""


class DeviceBusy(DeviceError):
    """The instrument answered but could not do it now (e.g. MT-SICS ``I``, a scan already running)."""
