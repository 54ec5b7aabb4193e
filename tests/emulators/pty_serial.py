"""A serial instrument on a pseudo-terminal: the driver opens ``port`` (the pty slave) with its real termios
and timeout code; a thread reads its commands on the master side and writes the replies a handler returns.

Replies: a ``str`` is one line (CR LF added); ``bytes`` are written raw (garbage, a line without its end);
``Pause(s)`` waits between chunks (a reply split in time); ``None`` or ``[]`` is silence. ``ExpectedProtocol``
asserts the exact command/reply exchange and that every pair was consumed (after pymeasure's
``expected_protocol``).
"""

from __future__ import annotations

import contextlib
import os
import select
import threading
import time
import tty
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class Pause:
    seconds: float


Reply = str | bytes | Pause

Handler = Callable[[str], Reply | Iterable[Reply] | None]


class PtySerialEmulator:
    """Runs ``handler`` for every CR LF (or LF) terminated command the driver sends."""

    def __init__(self, handler: Handler) -> None:
        self.handler = handler
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.port = os.ttyname(self._slave)
        self.received: list[str] = []
        self.errors: list[BaseException] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"emulator {self.port}", daemon=True)

    def __enter__(self) -> PtySerialEmulator:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def stop(self) -> None:
        self._close()
        if self.errors:
            raise self.errors[0]

    def unplug(self) -> None:
        """The instrument goes away: the master closes, so the driver's next read or write fails (EIO)."""
        self._close()

    def _close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2)
        for fd in (self._master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)
        self._master = self._slave = -1

    def _run(self) -> None:
        buffer = b""
        while not self._stop.is_set():
            ready, _, _ = select.select([self._master], [], [], 0.02)
            if not ready:
                continue
            try:
                chunk = os.read(self._master, 1024)
            except OSError:
                time.sleep(0.01)  # no slave open right now
                continue
            buffer += chunk
            while True:
                cut = min((i for i in (buffer.find(b"\r\n"), buffer.find(b"\n")) if i >= 0), default=-1)
                if cut < 0:
                    break
                end = cut + (2 if buffer[cut:cut + 2] == b"\r\n" else 1)
                command, buffer = buffer[:cut].decode("ascii", errors="replace"), buffer[end:]
                self.received.append(command)
                try:
                    self._reply(self.handler(command))
                except BaseException as exc:  # surfaced in the test thread by stop()
                    self.errors.append(exc)

    def _reply(self, replies: Reply | Iterable[Reply] | None) -> None:
        if replies is None:
            return
        if isinstance(replies, str | bytes | Pause):
            replies = [replies]
        for item in replies:
            if isinstance(item, Pause):
                time.sleep(item.seconds)
            elif isinstance(item, str):
                os.write(self._master, item.encode("ascii") + b"\r\n")
            else:
                os.write(self._master, item)


class ExpectedProtocol:
    """Handler that checks each command against the next expected pair and answers with its reply."""

    def __init__(self, pairs: Sequence[tuple[str, Reply | Sequence[Reply] | None]]) -> None:
        self.pairs = list(pairs)
        self._next = 0

    def __call__(self, command: str) -> Reply | Sequence[Reply] | None:
        if self._next >= len(self.pairs):
            raise AssertionError(f"unexpected extra command {command!r} after {len(self.pairs)} expected")
        expected, reply = self.pairs[self._next]
        self._next += 1
        if command != expected:
            raise AssertionError(f"command #{self._next}: expected {expected!r}, got {command!r}")
        return reply

    def assert_consumed(self) -> None:
        assert self._next == len(self.pairs), (
            f"only {self._next} of {len(self.pairs)} expected commands were sent; next was "
            f"{self.pairs[self._next][0]!r}")
