"""Who is writing a campaign file: a sidecar ``.NAME.h5.writer`` beside it, and a lock on the file.

The writer holds an exclusive ``flock`` on the file (``labctl.storage.rollback``; the lock HDF5's readers
take too) for as long as it has the file open, and writes the sidecar (JSON:
process id, host, command, since when) when it opens the file and removes it when it closes it. The lock is
the truth (the kernel drops it when the process dies, even by SIGKILL); the sidecar only says who holds it.
A reader that finds the file locked reports "in use by labctl (pid N on HOST) since T" instead of an HDF5
error, and ``open_live`` reads the file without taking the lock (docs/storage.md, "Reading a running
campaign").
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import sys
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

LOCK_WORDS = ("unable to lock file", "lock file", "resource temporarily unavailable")


def sidecar_path(path: str | Path) -> Path:
    p = Path(path)
    return p.with_name(f".{p.name}.writer")


def mark_writer(path: str | Path) -> None:
    """Record this process as the file's writer (best effort: a read-only folder only loses the report)."""
    doc = {"pid": os.getpid(), "host": socket.gethostname(), "since_utc": datetime.now(UTC).isoformat(
        timespec="seconds"), "command": " ".join(["labctl", *sys.argv[1:]])[:300]}
    with contextlib.suppress(OSError):
        sidecar_path(path).write_text(json.dumps(doc) + "\n", encoding="utf-8")


def clear_writer(path: str | Path) -> None:
    """Remove the sidecar if it names this process."""
    info = writer_info(path)
    if info is not None and info.get("pid") == os.getpid() and info.get("host") == socket.gethostname():
        with contextlib.suppress(OSError):
            sidecar_path(path).unlink()


def writer_info(path: str | Path) -> dict[str, Any] | None:
    """The sidecar's record, or None when there is none (or it is unreadable)."""
    try:
        doc = json.loads(sidecar_path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return doc if isinstance(doc, dict) else None


def _alive(pid: object) -> bool:
    if not isinstance(pid, int) or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def is_lock_error(exc: BaseException) -> bool:
    text = str(exc).lower()
    return any(w in text for w in LOCK_WORDS)


def in_use_message(path: str | Path) -> str:
    """One line saying who writes the file and since when, and what to do."""
    info = writer_info(path)
    if info is not None and (info.get("host") != socket.gethostname() or _alive(info.get("pid"))):
        who = (f"in use by {info.get('command', 'labctl')} (pid {info.get('pid')} on {info.get('host')}) since "
               f"{info.get('since_utc')}")
    else:
        who = "in use by another process (it holds the file's HDF5 lock)"
    return (f"{path}: {who}; wait until it finishes, or read what it has stored so far without disturbing it "
            "(docs/storage.md, 'Reading a running campaign')")
