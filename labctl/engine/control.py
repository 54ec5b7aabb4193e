"""Pause, resume, abort and clean stop, honoured by the engine at its next safe point (between impacts)."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager


class StopRequested(Exception):
    """Raised inside the engine at a safe point after ``abort`` or ``stop``; carries the final status."""

    def __init__(self, status: str) -> None:
        super().__init__(status)
        self.status = status


class RunControl:
    """Thread-safe controls a UI, a signal handler or a script uses while the engine runs in another thread."""

    def __init__(self) -> None:
        self._running = threading.Event()
        self._running.set()
        self._status: str | None = None
        self._override: tuple[bool, int | None] | None = None
        self._lock = threading.Lock()

    def override_last_impact(self, accept: bool, attempt: int | None = None) -> None:
        """The technician's verdict on the step's latest impact: reject an accepted one (it is hit again) or
        accept a rejected one. Applied at the next safe point while the step is still acquiring; with
        ``attempt`` given it applies only if that impact is still the latest (not to a newer blow)."""
        with self._lock:
            self._override = (bool(accept), attempt)

    def take_override(self) -> tuple[bool, int | None] | None:
        with self._lock:
            verdict, self._override = self._override, None
        return verdict

    def pause(self) -> None:
        self._running.clear()

    def resume(self) -> None:
        self._running.set()

    def abort(self) -> None:
        """Stop at the next safe point; the campaign is marked aborted (it can still be resumed)."""
        self._finish("aborted")

    def stop(self) -> None:
        """Clean stop (Ctrl-C): the campaign is marked interrupted and is resumable."""
        self._finish("interrupted")

    def _finish(self, status: str) -> None:
        with self._lock:
            self._status = self._status or status
        self._running.set()

    @property
    def paused(self) -> bool:
        return not self._running.is_set()

    @property
    def stop_status(self) -> str | None:
        return self._status

    def checkpoint(self, on_pause: callable | None = None, on_resume: callable | None = None) -> None:  # type: ignore[valid-type]
        """Block while paused; raise StopRequested if a stop was asked for."""
        if self._status:
            raise StopRequested(self._status)
        if not self._running.is_set():
            if on_pause:
                on_pause()
            self._running.wait()
            if self._status:
                raise StopRequested(self._status)
            if on_resume:
                on_resume()


@contextmanager
def stop_on_hangup(control: RunControl) -> Iterator[None]:
    """While a campaign runs in the main thread: SIGTERM (a service stop, `kill`) and SIGHUP (the technician's SSH
    session dropped) ask the same clean stop after the current impact as a first Ctrl-C, so the file ends
    `interrupted` with the resume hint instead of staying `running`; a second SIGTERM interrupts at once. After
    a hangup the terminal is gone, so output goes to /dev/null instead of failing. Handlers restored on exit."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: object) -> None:
        if signum == signal.SIGHUP:
            null = os.open(os.devnull, os.O_WRONLY)
            for fd in (1, 2):
                os.dup2(null, fd)
            os.close(null)
        elif control.stop_status:
            raise KeyboardInterrupt
        with contextlib.suppress(OSError, ValueError):
            sys.stderr.write(f"\n{signal.Signals(signum).name}: stopping after the current impact; continue with "
                             "--resume\n")
        control.stop()

    before = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGHUP)}
    for sig in before:
        signal.signal(sig, handler)
    try:
        yield
    finally:
        for sig, old in before.items():
            signal.signal(sig, old)
