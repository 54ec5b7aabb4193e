"""A rollback journal under the campaign writer, so a process killed at any moment (even inside HDF5's own
flush) leaves a file that reopens exactly as of its last completed flush.

HDF5 rewrites its metadata (object headers, B-trees, heaps, the superblock) in place when it flushes, one
piece after another; a process killed half-way leaves some pieces new and some old, and the file may not open
again. The writer therefore hands HDF5 a ``RollbackFile`` (h5py's ``fileobj`` driver): before a byte that
belongs to the last flushed state is overwritten (or cut off by a truncation), the 4 KiB page holding it is
appended to the journal ``.NAME.h5.journal`` beside the file. Bytes past the flushed end of allocation need no
copy: the flushed state does not reference them. When a flush has completed, the journal is emptied (the
commit). A journal found non-empty when the file is next opened belongs to a writer that died before its
commit: its pages are written back and the file cut to its flushed length, which is that flush's file again.

Like the rest of the writer this protects against the death of the process (SIGKILL, a crash, a full disk),
not against the machine losing power: the journal is not fsync'ed, as every write reaches the kernel, which
keeps it when the process dies.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import struct
import time
import zlib
from pathlib import Path

import h5py

from labctl.errors import InputError
from labctl.storage.diskspace import superblock_eoa

PAGE = 4096
MAGIC = b"labctl-rollback-journal-1\n"
HEADER = struct.Struct("<QI")  # flushed length of the file, crc32 of it
RECORD = struct.Struct("<QII")  # page offset, length, crc32 of the page's bytes


class FileInUse(InputError):
    """Another process holds the file's lock (a running writer)."""


def journal_path(path: str | Path) -> Path:
    p = Path(path)
    return p.with_name(f".{p.name}.journal")


def flushed_length(fd: int) -> int:
    """The bytes the file's flushed state uses: HDF5's end of allocation (the file size when not known)."""
    size = os.fstat(fd).st_size
    eoa = superblock_eoa(fd)
    return size if eoa is None else min(eoa, size)


def _records(data: bytes) -> tuple[int, list[tuple[int, bytes]]] | None:
    """The flushed length and the saved pages of a journal (None: empty or not a journal); a torn last record
    (the process died while appending it, before it overwrote anything) is ignored."""
    if not data.startswith(MAGIC) or len(data) < len(MAGIC) + HEADER.size:
        return None
    length, crc = HEADER.unpack_from(data, len(MAGIC))
    if zlib.crc32(struct.pack("<Q", length)) != crc:
        return None
    pages, at = [], len(MAGIC) + HEADER.size
    while at + RECORD.size <= len(data):
        offset, n, crc = RECORD.unpack_from(data, at)
        page = data[at + RECORD.size:at + RECORD.size + n]
        if len(page) != n or zlib.crc32(page) != crc:
            break
        pages.append((offset, page))
        at += RECORD.size + n
    return length, pages


def roll_back(fd: int, journal: Path) -> bool:
    """Undo an uncommitted flush of the file open as ``fd`` from its journal; True when there was one. The
    caller holds the file's lock."""
    try:
        size = journal.stat().st_size
        if size > 2 * os.fstat(fd).st_size + 2**20:  # a journal holds at most each page of the file once
            raise InputError(f"{journal}: {size} bytes, more than a rollback journal of its campaign file can "
                             "hold; not applied (move it away to read the file as it is)")
        data = journal.read_bytes()
    except FileNotFoundError:
        return False
    parsed = _records(data)
    if parsed is not None:
        length, pages = parsed
        for offset, page in pages:  # each page once: as it was flushed
            os.pwrite(fd, page, offset)
        if os.fstat(fd).st_size > length:
            os.ftruncate(fd, length)
    journal.unlink(missing_ok=True)
    return parsed is not None


def recover(path: str | Path) -> bool:
    """Before reading a campaign file: roll back what a killed writer left unflushed (True when it did).
    Nothing happens while a writer holds the file (its journal is live) or when there is no journal."""
    journal = journal_path(path)
    if not journal.exists():
        return False
    try:
        fd = os.open(path, os.O_RDWR)
    except OSError as exc:
        raise InputError(f"{path}: a writer was killed while flushing it and the file needs its journal "
                         f"{journal.name} applied, which needs write access ({exc.strerror}); run "
                         "'labctl run … --resume' or any read as a user who may write the file") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return False  # a live writer: its journal is in use
        return roll_back(fd, journal)
    except OSError as exc:
        raise InputError(f"{path}: cannot apply the journal {journal.name} a killed writer left "
                         f"({exc.strerror or exc}); run 'labctl run … --resume' where the folder is writable") from None
    finally:
        os.close(fd)  # closing releases the lock


class RollbackFile:
    """The file object HDF5 writes a campaign through (h5py ``fileobj`` driver): page copies to the journal
    before overwrites, ``commit`` after each completed flush; holds the file's lock while open."""

    def __init__(self, path: str | Path) -> None:
        self.name = str(path)
        self.journal = journal_path(path)
        self.fd = os.open(path, os.O_RDWR)
        try:
            fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(self.fd)
            raise FileInUse(f"{path}: in use") from None
        try:
            self.recovered = roll_back(self.fd, self.journal)
        except BaseException:
            os.close(self.fd)
            raise
        self.pos = 0
        self.dropping = False  # after a failed write: nothing more reaches the file
        self._jfd: int | None = None
        self._saved: set[int] = set()
        self.limit = flushed_length(self.fd)

    # --- what h5py's fileobj driver calls
    def seek(self, offset: int, whence: int = 0) -> int:
        self.pos = offset if whence == 0 else self.pos + offset if whence == 1 else os.fstat(self.fd).st_size + offset
        return self.pos

    def tell(self) -> int:
        return self.pos

    def readinto(self, buf: memoryview) -> int:
        data = os.pread(self.fd, len(buf), self.pos)
        buf[:len(data)] = data
        self.pos += len(data)
        return len(data)

    def read(self, n: int = -1) -> bytes:
        data = os.pread(self.fd, n if n >= 0 else os.fstat(self.fd).st_size - self.pos, self.pos)
        self.pos += len(data)
        return data

    def write(self, data: bytes | memoryview) -> int:
        n = len(memoryview(data).cast("B"))
        if self.dropping:
            return n
        if self.pos < self.limit:
            self._save(self.pos, min(self.pos + n, self.limit))
        written = os.pwrite(self.fd, data, self.pos)
        self.pos += written
        return written

    def truncate(self, size: int | None = None) -> int:
        size = self.pos if size is None else size
        if self.dropping:
            return size
        if size < self.limit:
            self._save(size, self.limit)
        os.ftruncate(self.fd, size)
        return size

    def flush(self) -> None:
        """HDF5's flush of the driver: everything is already with the kernel."""

    def __repr__(self) -> str:
        return self.name  # what h5py reports as the file's name

    # --- the journal
    def _save(self, start: int, end: int) -> None:
        """Copy the flushed bytes of every page of [start, end) not copied since the last commit."""
        if self._jfd is None:
            self._jfd = os.open(self.journal, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_APPEND, 0o644)
            length = struct.pack("<Q", self.limit)
            os.write(self._jfd, MAGIC + HEADER.pack(self.limit, zlib.crc32(length)))
        out = []
        for page in range(start // PAGE, (end - 1) // PAGE + 1):
            if page in self._saved:
                continue
            offset = page * PAGE
            data = os.pread(self.fd, min(PAGE, self.limit - offset), offset)
            out.append(RECORD.pack(offset, len(data), zlib.crc32(data)) + data)
            self._saved.add(page)
        if out:
            os.write(self._jfd, b"".join(out))

    def commit(self) -> None:
        """A flush has completed: the file as it is now is the state to come back to."""
        if self.dropping:
            return
        if self._jfd is not None:
            os.close(self._jfd)
            self._jfd = None
            self.journal.unlink(missing_ok=True)
        self._saved.clear()
        self.limit = flushed_length(self.fd)

    def abandon(self) -> None:
        """After a failed write: let nothing more reach the file, then undo what this flush changed."""
        self.dropping = True
        if self._jfd is not None:
            os.close(self._jfd)
            self._jfd = None
        with contextlib.suppress(OSError):
            roll_back(self.fd, self.journal)
        self._saved.clear()

    def close(self) -> None:
        """Release the file and its lock; HDF5 may still close its handle afterwards: that writes nothing."""
        self.dropping = True
        if self._jfd is not None:
            os.close(self._jfd)
            self._jfd = None
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1

    @property
    def closed(self) -> bool:
        return self.fd < 0


class JournaledFile(h5py.File):
    """An HDF5 file opened for writing through a ``RollbackFile``: every completed ``flush`` commits."""

    def __init__(self, path: str | Path) -> None:
        rollback = RollbackFile(path)
        try:
            super().__init__(rollback, "r+")
        except BaseException:
            rollback.close()
            raise
        self.rollback = rollback

    def flush(self) -> None:
        super().flush()
        self.rollback.commit()

    def close(self) -> None:
        rollback = getattr(self, "rollback", None)
        try:
            if self.id.valid:
                super().close()
                if rollback is not None:
                    rollback.commit()
        finally:
            if rollback is not None:
                rollback.close()

    def abandon(self) -> None:
        """Close without anything more reaching the file, which is left as of its last completed flush."""
        self.rollback.abandon()
        with contextlib.suppress(Exception):
            super().close()
        self.rollback.close()


def wait_for_flush(path: str | Path, timeout_s: float = 1.0) -> None:
    """A live reader's start: wait (up to ``timeout_s``) while the writer is inside a flush, i.e. while its
    journal exists, so the read starts on a flushed file; HDF5 reading metadata a flush is rewriting may fail
    or, rarely, crash. A flush that starts during the read is still possible: the read is checked after."""
    journal = journal_path(path)
    deadline = time.monotonic() + timeout_s
    while journal.exists() and time.monotonic() < deadline:
        time.sleep(0.005)
