"""Read a campaign a running ``labctl run`` is writing: read-only, without HDF5's lock, in the reading child of
``labctl.storage.isolated`` (HDF5 can crash on a torn read), retried until a read succeeds."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from labctl.errors import InputError
from labctl.storage.isolated import call_isolated
from labctl.storage.reader import CampaignReader

T = TypeVar("T")
LIVE_ATTEMPTS = 5
LIVE_RETRY_S = 0.2


def _read_with(path: str | Path, read: Callable[[CampaignReader], T]) -> T:  # runs in the reading child
    with CampaignReader(path, live=True) as reader:
        return read(reader)


def read_live(path: str | Path, read: Callable[[CampaignReader], T], *, attempts: int = LIVE_ATTEMPTS,
              retry_s: float = LIVE_RETRY_S) -> T:
    """``read(reader)`` (a module-level function with a picklable result) on a live campaign; a read that meets
    a flush half-way raises or crashes the child and is done again after ``retry_s`` (only groups marked
    complete are data). InputError after ``attempts`` (docs/storage.md)."""
    last: BaseException | None = None
    for attempt in range(attempts):
        try:
            return call_isolated(_read_with, path, read)
        except (OSError, KeyError, RuntimeError, ValueError, InputError) as exc:
            last = exc
            if attempt + 1 < attempts:
                time.sleep(retry_s)
    raise InputError(f"{path}: no consistent read of the running campaign in {attempts} attempts ({last})")
