"""Read UFF58 time records (ASCII 58 or binary 58b) written by labctl or by another acquisition system.

The file is memory-mapped and split into data sets by their ``    -1`` delimiter lines; a 58b set is skipped
by the byte count its header states, so binary data can never be mistaken for a delimiter. Headers are parsed
by pyuff from their 13 lines alone; the values are decoded in one vectorised call (``np.frombuffer`` for 58b,
``np.fromstring`` for ASCII) instead of pyuff's value-by-value parsing, which is what makes a large campaign
slow to read. Anything the fast path does not recognise (uneven abscissa, an irregular layout) is handed to
pyuff whole. This module checks what pyuff does not: a file cut short (a data set without its closing
``-1``), a record shorter than its header says, records of one impact that disagree in length or sample
interval. Time records are grouped into impacts by load case (docs/contracts.md); a file whose load cases
repeat per channel (some exporters leave them 0) is grouped by the order of the records instead.
"""

from __future__ import annotations

import math
import mmap
import re
import warnings
from collections import Counter, defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from labctl.errors import InputError
from labctl.processing.npz import ImpactSet
from labctl.uff import mapping as m
from labctl.uff.manifest import format_load_cases

TAIL_BYTES = 256
STEP_ID = re.compile(r"(series \d+ run \d+ step \d+) impact \d+")  # id2 of a labctl export
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



def significant_digits(value: float, most: int = 15) -> int:
    """The fewest significant digits that write ``value`` exactly (how precisely a header stored it)."""
    for d in range(1, most + 1):
        if float(f"{value:.{d - 1}e}") == value:
            return d
    return most


def sample_rate_hz(increment_s: float) -> float:
    """The sample rate from a written sample interval: the simplest rate the interval's digits allow.

    UFF headers keep ~6 significant digits (E13.5), so 1/4.88281e-05 s is 20480.05 Hz; the true rate lies in
    the interval the last digit leaves open, and the roundest number there (20480 Hz) is taken.
    """
    if not (math.isfinite(increment_s) and increment_s > 0):
        raise InputError(f"sample interval {increment_s!r} s: expected a positive number")
    exp = math.floor(math.log10(increment_s))
    half = 0.5 * 10.0 ** (exp - significant_digits(increment_s) + 1)
    lo, hi = 1.0 / (increment_s + half), 1.0 / (increment_s - half) if increment_s > half else math.inf
    raw = 1.0 / increment_s
    for decimals in range(-math.floor(math.log10(raw)), 10):
        candidate = round(raw, decimals)
        if lo <= candidate <= hi:
            return float(candidate)
    return raw


@dataclass
class UffImpacts:
    """Impacts read from UFF time records, in the impacts-NPZ layout, with where each came from."""

    fs_hz: float
    force_n: np.ndarray
    accel_m_per_s2: np.ndarray
    channels: tuple[str, ...]
    load_cases: list[int]
    source: str
    ids: list[tuple[str, ...]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)  # records left out, how impacts were numbered

    def impact_set(self) -> ImpactSet:
        return ImpactSet(self.fs_hz, self.force_n, self.accel_m_per_s2, self.channels, self.source)


def _channel_order(name: str) -> tuple[str, str]:
    return name[:-1], name[-1]


def _roles(uff: UffFile, nodes: m.NodeMap) -> tuple[dict[int, tuple[str, float]], list[str]]:
    """Channel name and sign of each time record (``"force"`` for the hammer); what was left out."""
    time = [h for h in uff.headers if h.func_type == m.TIME_RESPONSE]
    if not time:
        kinds = sorted({h.func_type for h in uff.headers})
        raise InputError(f"{uff.path}: no UFF58 time records (function type 1; found types {kinds or 'none'}); "
                         "labctl needs the raw impacts, not spectra or FRFs")
    has_hammer = any(h.node == nodes.hammer for h in time)
    roles: dict[int, tuple[str, float]] = {}
    ignored: Counter[str] = Counter()
    for h in time:
        if h.node == nodes.hammer or (not has_hammer and h.ordinate_type == m.ORDINATE_FORCE):
            roles[h.index] = ("force", 1.0)
            continue
        ch = nodes.channel(h.node, h.direction)
        if ch is None:
            ignored[f"node {h.node} dir {h.direction}"] += 1
        elif h.ordinate_type == m.ORDINATE_FORCE:
            raise InputError(f"{uff.path}: data set {h.index + 1} (node {h.node}) is a force record at an "
                             f"accelerometer node; node map {nodes.describe()}")
        else:
            roles[h.index] = ch
    if not any(r[0] == "force" for r in roles.values()):
        raise InputError(f"{uff.path}: no hammer force record (node {nodes.hammer} or ordinate type 13); "
                         "give the hammer's node with --nodes hammer=N")
    return roles, [f"ignored {n} record{'s' if n > 1 else ''} at {k} (not in node map {nodes.describe()})"
                   for k, n in sorted(ignored.items())]


def _group(uff: UffFile, roles: dict[int, tuple[str, float]]) -> tuple[dict[int, dict[str, int]], bool]:
    """Impact number → channel → data set index, and whether the numbers are the file's load cases.

    When a load case holds a channel more than once (the exporter left the load cases 0, say), the impacts
    are the n-th record of every channel and are numbered 1, 2, … in file order.
    """
    seen: Counter[tuple[int, str]] = Counter()
    impacts: dict[tuple[int, int], dict[str, int]] = defaultdict(dict)
    for h in uff.headers:
        if h.index not in roles:
            continue
        name = roles[h.index][0]
        k = seen[(h.load_case_id, name)]
        seen[(h.load_case_id, name)] += 1
        impacts[(h.load_case_id, k)][name] = h.index
    if all(k == 0 for _, k in impacts):
        return {lc: members for (lc, _), members in sorted(impacts.items())}, True
    ordered = sorted(impacts.items(), key=lambda item: (item[0][1], item[0][0]))
    return {i: members for i, (_, members) in enumerate(ordered, start=1)}, False


@dataclass
class ImpactPlan:
    """The time records of the chosen impacts, checked at header level; ``read`` loads their data."""

    uff: UffFile
    roles: dict[int, tuple[str, float]]
    groups: dict[int, dict[str, int]]
    channels: tuple[str, ...]
    by_load_case: bool
    notes: list[str]

    def read(self) -> UffImpacts:
        by_index = {h.index: h for h in self.uff.headers}
        first = by_index[next(iter(self.groups.values()))["force"]]
        force, accel, ids = [], [], []
        for members in self.groups.values():
            force.append(_record(self.uff, by_index[members["force"]], 1.0, accel=False))
            accel.append(np.stack([_record(self.uff, by_index[members[c]], self.roles[members[c]][1], accel=True)
                                   for c in self.channels]))
            ids.append(by_index[members["force"]].ids)
        fs = sample_rate_hz(first.abscissa_inc) if first.abscissa_inc > 0 else _rate_from_abscissa(self.uff, first)
        return UffImpacts(fs, np.stack(force), np.stack(accel), self.channels, list(self.groups), str(self.uff.path),
                          ids, list(self.notes))


def plan_uff_impacts(source: str | Path | UffFile, nodes: m.NodeMap = m.DEFAULT_NODES,
                     load_cases: Iterable[int] | None = None) -> ImpactPlan:
    """Find and check (headers only) the impacts of a UFF58 file, optionally only the given load cases."""
    uff = source if isinstance(source, UffFile) else UffFile(source)
    roles, notes = _roles(uff, nodes)
    groups, by_load_case = _group(uff, roles)
    if not by_load_case:
        notes.append("load cases repeat per channel: impacts numbered 1, 2, … in file order")
    if load_cases is not None:
        wanted = set(load_cases)
        missing = sorted(wanted - set(groups))
        if missing:
            raise InputError(f"{uff.path}: no time records for load case(s) {missing} (the file has "
                             f"{format_load_cases(list(groups))})")
        groups = {k: v for k, v in groups.items() if k in wanted}
    by_index = {h.index: h for h in uff.headers}
    channels = tuple(sorted((c for c in next(iter(groups.values())) if c != "force"), key=_channel_order))
    if not channels:
        raise InputError(f"{uff.path}: no accelerometer records at nodes {nodes.describe()}")
    first: Header | None = None
    for lc, members in groups.items():
        label = f"{uff.path}: " + (f"load case {lc}" if by_load_case else f"impact {lc}")
        got = tuple(sorted((c for c in members if c != "force"), key=_channel_order))
        if "force" not in members or got != channels:
            raise InputError(f"{label}: has {'a' if 'force' in members else 'no'} force record and channels "
                             f"{', '.join(got) or 'none'}; expected one force record and {', '.join(channels)}")
        first = first or by_index[members["force"]]
        for name, i in members.items():
            _check_like(uff, by_index[i], first)
            m.unit_factor(by_index[i].units, name != "force", _where(uff, by_index[i]))
    return ImpactPlan(uff, roles, groups, channels, by_load_case, notes)


def read_uff_impacts(source: str | Path | UffFile, nodes: m.NodeMap = m.DEFAULT_NODES,
                     load_cases: Iterable[int] | None = None) -> UffImpacts:
    """The impacts (optionally only those of the given load cases) of a UFF58 file's time records."""
    return plan_uff_impacts(source, nodes, load_cases).read()


def _rate_from_abscissa(uff: UffFile, header: Header) -> float:
    x, _ = uff.data(header)
    if len(x) < 2:
        raise InputError(f"{uff.path}: data set {header.index + 1} has fewer than two samples")
    steps = np.diff(x)
    if np.ptp(steps) > 1e-3 * np.mean(steps):
        raise InputError(f"{uff.path}: data set {header.index + 1} is not evenly sampled")
    return sample_rate_hz(float(f"{(x[-1] - x[0]) / (len(x) - 1):.6g}"))


def _where(uff: UffFile, h: Header) -> str:
    return f"{uff.path}: data set {h.index + 1} (node {h.node}, dir {h.direction}, load case {h.load_case_id})"


def _check_like(uff: UffFile, h: Header, first: Header) -> None:
    """Every record of the impacts has the first force record's length and sample interval."""
    if h.num_pts != first.num_pts:
        raise InputError(f"{_where(uff, h)}: {h.num_pts} samples where the first force record has {first.num_pts}")
    if not math.isclose(h.abscissa_inc, first.abscissa_inc, rel_tol=1e-6):
        raise InputError(f"{_where(uff, h)}: sample interval {h.abscissa_inc:g} s differs from the first force "
                         f"record's {first.abscissa_inc:g} s")


def _record(uff: UffFile, h: Header, sign: float, *, accel: bool) -> np.ndarray:
    _, y = uff.data(h)
    if np.iscomplexobj(y):
        raise InputError(f"{_where(uff, h)}: complex values in a time record")
    return sign * m.unit_factor(h.units, accel, _where(uff, h)) * y.astype(float)


def load_impacts_uff(path: str | Path, nodes: m.NodeMap = m.DEFAULT_NODES) -> ImpactSet:
    """A UFF58 file's time records as the impacts set ``labctl identify`` processes (same type as the NPZ).

    A labctl export of several load steps is refused: its impacts must not be averaged into one FRF.
    """
    impacts = read_uff_impacts(path, nodes)
    steps = {match.group(1) for ids in impacts.ids if (match := STEP_ID.match(ids[1] if len(ids) > 1 else ""))}
    if len(steps) > 1:
        raise InputError(f"{path}: holds the impacts of {len(steps)} load steps; identify one step at a time "
                         "(labctl export --step N) or make a campaign of them with labctl import")
    return impacts.impact_set()
