"""The engine's run log: every incident of a run stored in the campaign file as it happens.

Retries of instrument calls and blows, suspends and the resumes after them, pauses, operator prompts with their
answers, warnings and notices become ``LogEntry`` rows of the file's ``/log``. The engine passes each event it
emits through ``RunLog.record`` before its subscribers see it, so the log does not depend on any subscriber.

A write that fails does not stop the acquisition (the impacts are what the campaign is for) and is never
silent: the entry is kept and written with the next one, the operator gets one error notice, and entries still
unstored when the run ends are named in its outcome and written to the Python log.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Protocol

from labctl import events as ev
from labctl.storage import LogEntry
from labctl.storage.writer import utc_now

log = logging.getLogger("labctl.engine.runlog")


class LogSink(Protocol):
    """Where entries go (the campaign store)."""

    def append_log(self, entry: LogEntry) -> None: ...


def entry_fields(event: ev.Event) -> tuple[str, str, str] | None:
    """(level, kind, message) of an event the log keeps; None for the others (impacts and steps are stored
    in their own groups)."""
    if isinstance(event, ev.Notice):
        return event.level, event.kind, event.message
    if isinstance(event, ev.Suspended):
        return "warning", "suspend", event.reason
    if isinstance(event, ev.Resumed):
        return "info", "resume", event.reason or "resumed after a pause"
    if isinstance(event, ev.Paused):
        return "info", "pause", "paused at a safe point"
    if isinstance(event, ev.OperatorPrompted):
        return "info", "prompt", f"{event.action}: {event.message} → {event.answer}"
    if isinstance(event, ev.CampaignStarted):
        verb = "resumed" if event.resumed else "started"
        return "info", "start", f"campaign {verb}: protocol {event.protocol}, backend {event.backend}"
    return None


class RunLog:
    """Turns engine events into stored log entries, in order, holding back (never dropping) what fails."""

    def __init__(self, sink: LogSink, tell: Callable[[str], None]) -> None:
        """``tell`` reaches the operator without being logged itself (it reports on the log)."""
        self.sink, self.tell = sink, tell
        self.position = ev.Position(0, 0)  # where the engine last reported being
        self.pending: list[LogEntry] = []
        self.error = ""

    def record(self, event: ev.Event) -> None:
        """Store the event's entry (if it is one the log keeps), after any entries held back before it."""
        pos = getattr(event, "position", None)
        if isinstance(pos, ev.Position):
            self.position = pos
        what = entry_fields(event)
        if what is None:
            return
        p = self.position
        self.pending.append(LogEntry(utc_now(), p.series, p.run, p.step, p.impact, *what))
        self.flush()

    def flush(self) -> bool:
        """Write every held-back entry; False when some are still unstored."""
        while self.pending:
            try:
                self.sink.append_log(self.pending[0])
            except Exception as exc:  # a broken file or disk must not end the acquisition; it is reported
                if not self.error:
                    self.tell(f"run log: cannot write to the campaign file ({type(exc).__name__}: {exc}); "
                              "entries are kept and written when it works again")
                self.error = f"{type(exc).__name__}: {exc}"
                return False
            self.pending.pop(0)
        if self.error:
            self.tell("run log: writing works again; the held-back entries are stored")
            self.error = ""
        return True

    def close(self) -> str:
        """A last attempt at held-back entries; returns what to add to the run's outcome ("" when all stored)."""
        if self.flush():
            return ""
        for entry in self.pending:
            log.error("run log entry not stored: %s", entry)
        return f"{len(self.pending)} run-log entries could not be stored ({self.error})"
