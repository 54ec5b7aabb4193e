"""Output safety: no output ever overwrites an input, and a derived output appears whole or not at all.

Every command that writes names its inputs to ``check_outputs`` before writing anything: an output that is
an input (the same path, a hard link or a symbolic link to it) is refused with one line naming both, and so
is an output that would replace an existing campaign file or labctl catalogue (acquired data is never
lost). ``atomic_output`` writes to a temporary name in the target's folder and renames it over the target
only when the writer finished, so a crash, a full disk or an error leaves the old file (or none), never half
a file.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from labctl.errors import InputError

HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
SQLITE_MAGIC = b"SQLite format 3\x00"
PathLike = str | os.PathLike[str]


def _key(path: PathLike) -> tuple[str, tuple[int, int] | None]:
    """The resolved path and, for an existing file, its (device, inode): hard links share the second."""
    p = Path(path)
    try:
        st = p.stat()
        ident: tuple[int, int] | None = (st.st_dev, st.st_ino)
    except OSError:
        ident = None
    return os.path.realpath(p), ident


def same_file(a: PathLike, b: PathLike) -> bool:
    """True when ``a`` and ``b`` name the same file (same path after links, or the same inode)."""
    (ra, ia), (rb, ib) = _key(a), _key(b)
    return ra == rb or (ia is not None and ia == ib)


def _magic(path: PathLike) -> bytes:
    try:
        with open(path, "rb") as fh:
            return fh.read(16)
    except OSError:
        return b""


def check_outputs(outputs: Iterable[tuple[str, PathLike | None]], inputs: Iterable[PathLike | None], *,
                  allow_campaign: bool = False) -> None:
    """Refuse (InputError) any output that names one of ``inputs``, another output, or an existing campaign
    file or SQLite database (unless ``allow_campaign``: the catalogue a command updates in place).

    ``outputs`` are (option, path) pairs, e.g. ("--csv", "t.csv"); None entries are skipped."""
    ins = [p for p in inputs if p is not None]
    seen: list[tuple[str, PathLike]] = []
    for option, out in outputs:
        if out is None:
            continue
        for inp in ins:
            if same_file(out, inp):
                raise InputError(f"{option} {out}: is the input {inp}; choose another output name "
                                 "(an output never overwrites an input)")
        for other_option, other in seen:
            if same_file(out, other):
                raise InputError(f"{option} {out}: is also the output of {other_option}; choose two names")
        seen.append((option, out))
        if not allow_campaign and Path(out).is_file():
            head = _magic(out)
            if head.startswith(HDF5_MAGIC) or head.startswith(SQLITE_MAGIC):
                kind = "an HDF5 (campaign) file" if head.startswith(HDF5_MAGIC) else "an SQLite database"
                raise InputError(f"{option} {out}: exists and is {kind}; choose another output name "
                                 "(labctl never replaces acquired data or a catalogue with a derived file)")


@contextmanager
def atomic_output(path: PathLike) -> Iterator[Path]:
    """A temporary path beside ``path`` to write to; renamed over ``path`` when the block ends without error,
    removed otherwise. The rename is atomic on one file system, so readers see the old file or the new one."""
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part", dir=folder)
    except OSError as exc:
        raise InputError(f"{target}: cannot write here ({exc.strerror or exc})") from None
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        os.chmod(tmp, 0o644)  # mkstemp makes 0o600; a derived file is as readable as any other
        yield tmp
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def output_folder(option: str, path: PathLike) -> Path:
    """The folder an option names, made if missing; one line naming the option when it cannot be (a file is in
    the way, no permission, a read-only or full file system)."""
    folder = Path(path)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise InputError(f"{option} {folder}: exists and is not a folder") from None
    except OSError as exc:
        raise InputError(f"{option} {folder}: cannot make the folder ({exc.strerror or exc})") from None
    return folder
