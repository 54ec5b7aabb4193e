"""Disk-full safety for the campaign writer: room is reserved before each impact, and a write that still
fails leaves the file as it was at its last flush.

``reserve`` allocates the blocks the next writes will need (``posix_fallocate`` from HDF5's end of
allocation, read from the superblock), so a full disk or a file-size limit is met there, before anything of
the impact is written, and the writer stops cleanly. Where the file system cannot preallocate, the free
space is compared instead.

(The campaign writer's own files are written through a rollback journal, ``labctl.storage.rollback``, which
``discard`` uses instead: it undoes every write since the last flush. The descriptor trick below is kept for
files opened with HDF5's own driver.)

HDF5 keeps changed metadata in memory and writes it when the file is flushed or closed. After a failed
write (ENOSPC on a full disk, EFBIG past a file-size limit) that flush would write half a file: the
superblock would name an end of file that was never written, and the file could not be opened again. So
``discard`` points the file's descriptor at /dev/null before closing the handle: whatever HDF5 still holds
goes nowhere, and the file on disk stays the consistent one of the last flush (plus unreferenced bytes at its
end). The writer then reopens it, drops the partial impact and records why it stopped.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import resource
import shutil
from pathlib import Path

import h5py

from labctl.errors import LabctlError

RESERVE_BYTES = 4 * 2**20
"""Room kept free for what follows the last impact: step result, FRF, curve, log entries, final status."""
FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EFBIG, errno.EDQUOT})


class DiskFull(LabctlError):
    """The campaign file cannot grow (disk full, quota or file-size limit); the file is kept resumable."""


def free_bytes(path: str | Path) -> int:
    """Bytes ``path`` (an existing file) may still grow by: free disk space, within this process's file-size
    limit (RLIMIT_FSIZE) when there is one."""
    p = Path(path)
    free = shutil.disk_usage(p.parent if str(p.parent) else ".").free
    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    if soft != resource.RLIM_INFINITY:
        free = min(free, max(soft - p.stat().st_size, 0))
    return int(free)


def superblock_eoa(fd: int) -> int | None:
    """HDF5's end-of-allocation address as last flushed to the superblock (None: a layout not known here).

    Superblock versions 0 and 1 keep it at byte 40 (44), versions 2 and 3 at byte 28, with 8-byte offsets."""
    head = os.pread(fd, 48, 0)
    if len(head) < 48 or not head.startswith(b"\x89HDF\r\n\x1a\n"):
        return None
    version = head[8]
    where, sizeof_offsets = {0: (40, head[13]), 1: (44, head[13]), 2: (28, head[9]), 3: (28, head[9])}.get(
        version, (0, 0))
    if sizeof_offsets != 8:
        return None
    return int.from_bytes(head[where:where + 8], "little")


def file_fd(h5: h5py.File) -> int:
    """The descriptor HDF5 writes the file through (the rollback journal's, for the campaign writer)."""
    rollback = getattr(h5, "rollback", None)
    return rollback.fd if rollback is not None else int(h5.id.get_vfd_handle())


def reserve(h5: h5py.File, need_bytes: int) -> None:
    """Allocate room for the file to grow by ``need_bytes`` past HDF5's end of allocation, or raise DiskFull
    naming what is left; nothing of the file's content is changed either way."""
    fd = file_fd(h5)
    size = os.fstat(fd).st_size
    eoa = superblock_eoa(fd)
    start = size if eoa is None or eoa > size else eoa
    try:
        os.posix_fallocate(fd, start, need_bytes)
        return
    except OSError as exc:
        if exc.errno not in FULL_ERRNOS and exc.errno not in (errno.EOPNOTSUPP, errno.EINVAL, errno.ENOSYS):
            raise
        if exc.errno in FULL_ERRNOS:
            raise DiskFull(f"disk full ({free_bytes(h5.filename) / 2**20:.1f} MiB left, "
                           f"{need_bytes / 2**20:.1f} MiB needed)") from None
    free = free_bytes(h5.filename)  # no preallocation on this file system: compare instead
    if free < need_bytes:
        raise DiskFull(f"disk full ({free / 2**20:.1f} MiB left, {need_bytes / 2**20:.1f} MiB needed)")


def trim(h5: h5py.File) -> None:
    """After a flush: give back the room ``reserve`` allocated and HDF5 did not use (the file ends at HDF5's
    end of allocation again). Never raises: an untrimmed file is only larger."""
    with contextlib.suppress(Exception):
        fd = file_fd(h5)
        eoa = superblock_eoa(fd)
        if eoa is not None and 0 < eoa < os.fstat(fd).st_size:
            os.ftruncate(fd, eoa)


def is_full(exc: BaseException) -> bool:
    """True when an OSError (h5py's included, which name the errno only in their text) means 'no room'."""
    if isinstance(exc, OSError) and exc.errno in FULL_ERRNOS:
        return True
    m = re.search(r"errno = (\d+)", str(exc))
    return bool(m and int(m.group(1)) in FULL_ERRNOS) or "No space left" in str(exc) or "too large" in str(exc)


def discard(h5: h5py.File | None) -> None:
    """Close ``h5`` without writing anything more to its file (see the module docstring); never raises."""
    if h5 is None:
        return
    if hasattr(h5, "abandon"):  # the campaign writer's file: its journal undoes the unflushed writes
        h5.abandon()
        return
    try:
        if not h5.id.valid:
            return
        fd = h5.id.get_vfd_handle()
    except Exception:  # noqa: BLE001 — a broken handle: closing is all that is left
        fd = None
    if isinstance(fd, int) and fd >= 0:
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(null, fd)
        finally:
            os.close(null)
    with contextlib.suppress(Exception):  # the writes went to /dev/null; a complaint about them is moot
        h5.close()
