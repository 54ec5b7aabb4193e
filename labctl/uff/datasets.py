"""UFF files as memory-mapped data sets: the ``    -1`` framing, 58/58b headers (parsed by pyuff from their 13
lines alone) and each set's values decoded in one vectorised call; pyuff reads whole what the fast path does not
recognise. A file cut short, or a record shorter than its header says, is an InputError naming the file."""


from __future__ import annotations

import mmap
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from labctl.errors import InputError

TAIL_BYTES = 256
DELIMITER = b"    -1"
HEADER_LINES_58 = 13  # the delimiter, the type line, id1-id5 and six record lines


@dataclass(frozen=True)
class Header:
    """The header fields labctl uses of one UFF58 data set (``index`` counts every data set from 0)."""

    index: int
    func_type: int
    load_case_id: int
    node: int
    direction: int
    ref_node: int
    ordinate_type: int
    units: str
    num_pts: int
    abscissa_inc: float
    abscissa_even: bool
    ids: tuple[str, ...]
    data_type: int = 4  # 2/4: real single/double; 5/6: complex single/double
    binary: bool = False
    little_endian: bool = True
    abscissa_min: float = 0.0


@dataclass(frozen=True)
class _Block:
    """One data set's place in the file: its opening delimiter, its values, its closing delimiter."""

    start: int
    body: int
    end: int
    set_type: int
    binary: bool


def _int(d: dict[str, Any], key: str) -> int:
    try:
        return int(d.get(key, 0))
    except (TypeError, ValueError):
        return 0


def _is_delimiter(mm: Any, at: int) -> bool:
    """A ``    -1`` line: at a line start and followed by the line end (or blanks to it)."""
    if mm[at:at + 6] != DELIMITER or (at > 0 and mm[at - 1:at] not in (b"\n", b"\r")):
        return False
    eol = mm.find(b"\n", at + 6)
    rest = mm[at + 6:len(mm) if eol < 0 else eol]
    return rest.strip() == b""


def _line_end(mm: Any, at: int, where: str) -> int:
    eol = mm.find(b"\n", at)
    if eol < 0:
        raise InputError(f"{where}: truncated UFF file (a data set header is cut short)")
    return eol + 1


def _scan(mm: Any, path: Path) -> list[_Block]:
    """Every data set of the file, found by its delimiters (58b sets by their stated byte count)."""
    blocks: list[_Block] = []
    pos = 0
    while True:
        start = mm.find(DELIMITER, pos)
        while start >= 0 and not _is_delimiter(mm, start):
            start = mm.find(DELIMITER, start + 1)
        if start < 0:
            return blocks
        where = f"{path}: data set {len(blocks) + 1}"
        type_at = _line_end(mm, start, where)
        type_line = mm[type_at:_line_end(mm, type_at, where)]
        try:
            set_type = int(type_line[:6])
        except ValueError:
            raise InputError(f"{where}: not a UFF data set (type line {type_line[:20]!r})") from None
        binary = type_line[6:7].lower() == b"b"
        body = type_at
        for _ in range(HEADER_LINES_58 - 1 if set_type == 58 else 1):
            body = _line_end(mm, body, where)
        end = -1
        if binary and set_type == 58:
            end = _binary_end(mm, bytes(mm[start:body]).splitlines(), body, where)
        else:
            end = mm.find(b"\n" + DELIMITER, body - 1)
            while end >= 0 and not _is_delimiter(mm, end + 1):
                end = mm.find(b"\n" + DELIMITER, end + 1)
            if end < 0:
                raise InputError(f"{path}: truncated UFF file (the last data set has no closing '-1' line)")
            end += 1
        blocks.append(_Block(start, body, end, set_type, binary))
        pos = end + 6


def _delimiter_after(mm: Any, at: int) -> int:
    """Where the closing ``    -1`` of a 58b set begins when its values end at ``at`` (-1: it does not)."""
    while at < len(mm) and mm[at:at + 1] in (b"\n", b"\r", b" ") and mm[at:at + 6] != DELIMITER:
        at += 1
    return at if mm[at:at + 6] == DELIMITER else -1


def _binary_end(mm: Any, header: list[bytes], body: int, where: str) -> int:
    """The closing delimiter of a 58b set: after the values its header describes, or its stated byte count.

    pyuff states half the true byte count for complex values, so the count implied by the number of points
    and the data type is tried first.
    """
    try:
        stated = int(header[1][31:43])
        data_type, points = int(header[8][:10]), int(header[8][10:20])  # record 7: data type, number of points
    except (ValueError, IndexError):
        raise InputError(f"{where}: unreadable 58b header ({header[1].strip()[:60]!r})") from None
    implied = points * (2 if data_type in (5, 6) else 1) * (4 if data_type in (2, 5) else 8)
    for n_bytes in dict.fromkeys((implied, stated)):
        end = _delimiter_after(mm, body + n_bytes)
        if end >= 0:
            return end
    raise InputError(f"{where}: shorter than the {implied} bytes its header announces (file truncated or corrupt)")


class UffFile:
    """An existing UFF file, memory-mapped; every problem is an InputError naming the file."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise InputError(f"{self.path}: " + ("is a directory, expected a UFF file" if self.path.is_dir()
                                                 else "file not found"))
        self._check_framing()
        self._fh = self.path.open("rb")
        self._mm = mmap.mmap(self._fh.fileno(), 0, access=mmap.ACCESS_READ)
        self._pyuff: Any = None
        self.blocks = _scan(self._mm, self.path)
        if not self.blocks:
            raise InputError(f"{self.path}: no UFF data sets found (expected blocks between '    -1' lines)")
        self.set_types = [b.set_type for b in self.blocks]
        self.headers = [self._header(i) for i, t in enumerate(self.set_types) if t == 58]

    def close(self) -> None:
        self._mm.close()
        self._fh.close()

    def _check_framing(self) -> None:
        size = self.path.stat().st_size
        with self.path.open("rb") as fh:
            head = fh.read(TAIL_BYTES)
            fh.seek(max(0, size - TAIL_BYTES))
            tail = fh.read()
        if not head.lstrip().startswith(b"-1"):
            raise InputError(f"{self.path}: not a UFF file (it does not begin with a '    -1' line)")
        if not tail.rstrip().endswith(b"-1"):
            raise InputError(f"{self.path}: truncated UFF file (the last data set has no closing '-1' line)")

    def _read(self, index: int) -> dict[str, Any]:
        """The whole data set parsed by pyuff (the slow path, for layouts the fast one does not know)."""
        import pyuff

        try:
            if self._pyuff is None:
                self._pyuff = pyuff.UFF(str(self.path))
            dset = self._pyuff.read_sets(index, header_only=False)
        except Exception as exc:  # pyuff raises bare Exception
            raise InputError(f"{self.path}: data set {index + 1} cannot be read ({exc})") from None
        if not isinstance(dset, dict):
            raise InputError(f"{self.path}: data set {index + 1} cannot be read")
        return dset

    def _header(self, index: int) -> Header:
        from pyuff.datasets.dataset_58 import _extract58

        b = self.blocks[index]
        try:
            d = _extract58(bytes(self._mm[b.start:b.body]), header_only=True)
        except Exception as exc:  # pyuff raises bare Exception
            raise InputError(f"{self.path}: data set {index + 1} cannot be read ({exc})") from None
        points, room = _int(d, "num_pts"), b.end - b.body
        if not 1 <= points <= room:  # every value takes at least a byte: a larger count is refused before any read
            raise InputError(f"{self.path}: data set {index + 1} announces {points} points in {room} bytes of "
                             "data (file truncated, corrupt or crafted)")
        return Header(index=index, func_type=_int(d, "func_type"), load_case_id=_int(d, "load_case_id"),
                      node=_int(d, "rsp_node"), direction=_int(d, "rsp_dir"), ref_node=_int(d, "ref_node"),
                      ordinate_type=_int(d, "ordinate_spec_data_type"),
                      units=str(d.get("ordinate_axis_units_lab", "")).strip(), num_pts=_int(d, "num_pts"),
                      abscissa_inc=float(d.get("abscissa_inc", 0.0) or 0.0),
                      abscissa_even=bool(_int(d, "abscissa_spacing")),
                      ids=tuple(str(d.get(f"id{i}", "")).strip() for i in range(1, 6)),
                      data_type=_int(d, "ord_data_type"), binary=b.binary,
                      little_endian=_int(d, "byte_ordering") == 1,
                      abscissa_min=float(d.get("abscissa_min", 0.0) or 0.0))

    def _values(self, header: Header) -> np.ndarray | None:
        """The set's values decoded in one call, or None when its layout needs pyuff."""
        b = self.blocks[header.index]
        if not header.abscissa_even or header.data_type not in (2, 4, 5, 6):
            return None
        count = header.num_pts * (2 if header.data_type in (5, 6) else 1)
        if header.binary:
            dtype = np.dtype(("<" if header.little_endian else ">") + ("f4" if header.data_type in (2, 5) else "f8"))
            if b.end - b.body < count * dtype.itemsize:
                return None
            values = np.frombuffer(self._mm, dtype=dtype, count=count, offset=b.body).astype(float)
        else:
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                try:
                    values = np.fromstring(self._mm[b.body:b.end], dtype=float, sep=" ")
                except (ValueError, DeprecationWarning):
                    return None
            if len(values) != count:  # parsed, but not what the header announces: data() says so
                return values
        return values[0::2] + 1j * values[1::2] if header.data_type in (5, 6) else values

    def data(self, header: Header) -> tuple[np.ndarray, np.ndarray]:
        """(abscissa, ordinate) of a data set, checked against its header's point count."""
        values = self._values(header)
        if values is None:
            d = self._read(header.index)
            y, x = np.asarray(d.get("data")), np.asarray(d.get("x"), dtype=float)
        else:
            y = values
            x = header.abscissa_min + header.abscissa_inc * np.arange(len(y))
        where = f"{self.path}: data set {header.index + 1}"
        if y.ndim != 1 or len(y) != header.num_pts or len(x) != len(y):
            raise InputError(f"{where}: holds {y.size} values but its header announces {header.num_pts} "
                             "(file truncated or corrupt)")
        if not np.isfinite(y).all():
            raise InputError(f"{where}: holds a non-finite value at index {int(np.argmin(np.isfinite(y)))}")
        return x, y
