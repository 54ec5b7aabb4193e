"""The campaign file's run log: what happened during acquisition that the impacts and steps do not show.

Retries of an instrument call, suspends and resumes, pauses, operator prompts with their answers, warnings.
The log is one resizable HDF5 table, ``/log/entries``, of ``LogEntry`` rows; each entry is appended and
flushed on its own, so a crash loses at most the entry in flight. Files without a log (schema 1, or schema 2
written before the log existed) read as an empty log.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from dataclasses import astuple, dataclass, fields

import h5py
import numpy as np

from labctl.errors import InputError

LOG = "log"
ENTRIES = "entries"
LOG_CHUNK = 64  # rows per chunk of the log table


@dataclass(frozen=True)
class LogEntry:
    """One incident of a run: when (UTC), where (1-based series/run/step/impact; 0 = not inside one), how
    serious (``level``), what sort (``kind``: retry, suspend, resume, pause, prompt, verdict, notice, start)
    and what was said."""

    time_utc: str
    series: int
    run: int
    step: int
    impact: int
    level: str
    kind: str
    message: str


_TEXT = h5py.string_dtype("utf-8")
DTYPE = np.dtype([(f.name, np.int32 if f.type == "int" else _TEXT) for f in fields(LogEntry)])


def append_entry(h5: h5py.File, entry: LogEntry) -> None:
    """Append one entry to ``/log/entries`` (created on first use) and flush the file."""
    group = h5.require_group(LOG)
    table = group.get(ENTRIES)
    if table is None:
        table = group.create_dataset(ENTRIES, shape=(0,), maxshape=(None,), dtype=DTYPE, chunks=(LOG_CHUNK,))
        group.attrs["columns"] = ", ".join(DTYPE.names or ())
    n = table.shape[0]
    table.resize((n + 1,))
    table[n] = astuple(entry)
    h5.flush()


def _text(value: object) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def read_entries(h5: h5py.File) -> list[LogEntry]:
    """Every stored entry in the order written (empty when the file has no log)."""
    group = h5.get(LOG)
    table = None if group is None else group.get(ENTRIES)
    if table is None:
        return []
    names = getattr(table.dtype, "names", None) or ()
    if not isinstance(table, h5py.Dataset) or table.ndim != 1 or set(names) != set(DTYPE.names or ()):
        raise InputError(f"{h5.filename}:/{LOG}/{ENTRIES}: not a run log table (expected a 1-D table with "
                         f"columns {', '.join(DTYPE.names or ())})")
    out = []
    for i, row in enumerate(table[()]):
        try:
            values = {f.name: int(row[f.name]) if f.type == "int" else _text(row[f.name]) for f in fields(LogEntry)}
        except (TypeError, ValueError, UnicodeDecodeError) as exc:
            raise InputError(f"{h5.filename}:/{LOG}/{ENTRIES} row {i}: unreadable ({exc})") from None
        out.append(LogEntry(**values))
    return out


@dataclass(frozen=True)
class LogSummary:
    """Counts of a run log: all entries, per kind and per level."""

    entries: int
    by_kind: dict[str, int]
    by_level: dict[str, int]

    @property
    def warnings(self) -> int:
        return self.by_level.get("warning", 0)

    @property
    def errors(self) -> int:
        return self.by_level.get("error", 0)


def summarize(entries: Iterable[LogEntry]) -> LogSummary:
    entries = list(entries)
    return LogSummary(len(entries), dict(sorted(Counter(e.kind for e in entries).items())),
                      dict(sorted(Counter(e.level for e in entries).items())))
