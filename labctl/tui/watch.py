"""Follow a campaign file another process is writing (``labctl tui --watch FILE``), read-only.

The writer flushes the file after every impact; the watcher re-opens it read-only without HDF5's file lock at
each poll, in a child process (``labctl.storage.isolated``: HDF5 can crash on a torn read), reads what it needs,
and closes it. A read that catches a flush half-way fails, crashes the child, or is not an earlier state of a
second read taken right after it (the writer only appends); it is retried, and the screen keeps the last
consistent snapshot meanwhile.
Nothing here ever opens the file for writing.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

from labctl.errors import InputError
from labctl.report.notes import step_events
from labctl.storage import CampaignReader
from labctl.storage.isolated import call_isolated

FINAL = ("complete", "aborted", "interrupted", "interlock", "failed")


@dataclass(frozen=True)
class WatchedStep:
    """One stored step as the watcher shows it."""

    series: int
    run: int
    step: int
    load_n: float
    impacts: int
    accepted: int
    identified: bool
    bounce_hz: float
    stiffness_n_per_m: float
    notes: tuple[str, ...]
    complete: bool
    flags: tuple[str, ...] = ()  # the notes in a few words each


@dataclass(frozen=True)
class Snapshot:
    """What the file held at one consistent read."""

    path: str
    status: str
    protocol: str
    backend: str
    steps: tuple[WatchedStep, ...]
    log: tuple[str, ...]  # the run log's entries as lines

    @property
    def finished(self) -> bool:
        return self.status in FINAL

    @property
    def impacts(self) -> int:
        return sum(s.impacts for s in self.steps)

    @property
    def accepted(self) -> int:
        return sum(s.accepted for s in self.steps)

    def earlier_state_of(self, later: Snapshot) -> bool:
        """Whether this read is a state the file really passed through on its way to ``later``: the writer
        only appends, so every step read here is in ``later`` (a finished step alike, an unfinished one with no
        more impacts) and this run log is the start of that one. A read that caught a flush half-way is not."""
        if (self.path, self.protocol, self.backend) != (later.path, later.protocol, later.backend):
            return False
        if len(self.steps) > len(later.steps) or later.log[:len(self.log)] != self.log:
            return False
        for mine, theirs in zip(self.steps, later.steps, strict=False):
            if (mine.series, mine.run, mine.step) != (theirs.series, theirs.run, theirs.step):
                return False
            if mine.complete and repr(mine) != repr(theirs):  # NaN-safe: equal values print alike
                return False
            if not mine.complete and mine.impacts > theirs.impacts:
                return False
        return True


def _read(path: Path) -> Snapshot:
    with CampaignReader(path, locking=False) as reader:
        a = reader.attrs
        steps = []
        for series in reader.series_indices():
            for run in reader.runs(series):
                for st in run.steps:
                    r, happened = st.result, step_events(st)
                    ok = r is not None and r.identified
                    steps.append(WatchedStep(
                        series, run.run, st.step, st.load_n, len(st.impacts), st.accepted_count, ok,
                        r.bounce_hz if ok and r is not None else math.nan,
                        r.roller_stiffness_n_per_m if ok and r is not None else math.nan,
                        tuple(happened.notes()), st.complete, tuple(happened.flags())))
        log = tuple(f"{e.time_utc[11:19]} {e.level}: {e.message}" for e in reader.log())
        return Snapshot(str(path), str(a.get("status", "")), str(a.get("protocol_name", "")),
                        str(a.get("backend", "")), tuple(steps), log)


def read_snapshot(path: str | Path, attempts: int = 5, wait_s: float = 0.2) -> Snapshot:
    """A consistent snapshot of a campaign file being written: a read that a second read shows to be a state
    the file passed through (retried up to ``attempts`` times). InputError when the file does not exist, is no
    campaign, or never reads consistently."""
    p = Path(path)
    last = ""
    for _ in range(attempts):
        try:
            first = call_isolated(_read, p)
            if first.finished or first.earlier_state_of(call_isolated(_read, p)):
                return first
            last = "the file changed while it was read"
        except InputError as exc:
            if not p.exists() or "not a labctl campaign" in str(exc) or "format_version" in str(exc):
                raise
            last = str(exc)
        except (OSError, KeyError, ValueError, RuntimeError) as exc:  # a flush caught half-way (TornRead too)
            last = f"{type(exc).__name__}: {exc}"
        time.sleep(wait_s)
    raise InputError(f"{p}: could not read a consistent state in {attempts} tries ({last})")
