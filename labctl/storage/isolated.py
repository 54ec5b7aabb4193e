"""Reads of a file another process is writing, done in a child process.

HDF5 does not only raise on metadata torn by a concurrent flush: it can crash the process (a segmentation fault
seen while ``labctl tui --watch`` followed a running campaign). So every read of a live campaign runs in one
long-lived child process; a crash or a hang there costs that read (raised as ``TornRead``, and the caller
retries on a fresh child), never the watcher, the writer or the test run.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from collections.abc import Callable
from multiprocessing.connection import Connection
from typing import Any, TypeVar

T = TypeVar("T")

READ_TIMEOUT_S = 120.0
"""A read of a whole campaign takes seconds; a child silent for this long is taken as hung and killed."""


class TornRead(OSError):
    """The child reading a live file crashed or hung: the read met a state HDF5 could not survive; read again."""


def _serve(inbox: Connection, outbox: Connection) -> None:
    """The child's loop: call what it is sent, send back (True, value) or (False, the exception)."""
    while True:
        try:
            fn, args = inbox.recv()
        except (EOFError, OSError):
            return
        try:
            reply: tuple[bool, Any] = (True, fn(*args))
        except BaseException as exc:  # noqa: BLE001 - every failure goes back to the caller to judge
            reply = (False, exc)
        try:
            outbox.send(reply)
        except Exception as exc:  # noqa: BLE001 - an unpicklable value or exception: say what it was
            outbox.send((False, RuntimeError(f"{type(exc).__name__}: {exc}")))


class _Child:
    """One reading process (``python -m labctl.storage.isolated``, so no caller's main module is re-imported)
    and the two pipes to it."""

    def __init__(self) -> None:
        to_child_r, to_child_w = os.pipe()
        from_child_r, from_child_w = os.pipe()
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}  # the caller's modules
        self.proc = subprocess.Popen([sys.executable, "-m", __name__, str(to_child_r), str(from_child_w)],
                                     pass_fds=(to_child_r, from_child_w), env=env, stdin=subprocess.DEVNULL)
        os.close(to_child_r)
        os.close(from_child_w)
        self.outbox = Connection(to_child_w, readable=False)
        self.inbox = Connection(from_child_r, writable=False)

    def alive(self) -> bool:
        return self.proc.poll() is None

    def call(self, fn: Callable[..., T], args: tuple, timeout_s: float) -> T:
        try:
            self.outbox.send((fn, args))
        except OSError:
            self.close()
            raise TornRead(f"the reading process had died (exit {self.proc.returncode})") from None
        if not self.inbox.poll(timeout_s):
            self.close()
            raise TornRead(f"the reading process gave no answer in {timeout_s:g} s and was stopped")
        try:
            ok, value = self.inbox.recv()
        except (EOFError, OSError):
            self.close()
            raise TornRead(f"the reading process died (exit {self.proc.returncode}) on a state of the file HDF5 "
                           "could not read") from None
        if ok:
            return value
        raise value

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(5)
        self.outbox.close()
        self.inbox.close()


_lock = threading.Lock()
_child: _Child | None = None


def call_isolated(fn: Callable[..., T], *args: Any, timeout_s: float = READ_TIMEOUT_S) -> T:
    """``fn(*args)`` in the reading child (started on first use, restarted after a crash); ``fn`` must be a
    module-level function and its arguments and result picklable. Exceptions ``fn`` raises are raised here."""
    global _child
    with _lock:  # one read at a time through the one pipe
        if _child is None or not _child.alive():
            _child = _Child()
        child = _child
        try:
            return child.call(fn, args, timeout_s)
        except TornRead:
            _child = None
            raise


if __name__ == "__main__":
    _serve(Connection(int(sys.argv[1]), writable=False), Connection(int(sys.argv[2]), readable=False))
