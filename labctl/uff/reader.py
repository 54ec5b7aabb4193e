"""Impacts from UFF58 time records (ASCII 58 or binary 58b) written by labctl or by another acquisition system.

The records (read by :mod:`labctl.uff.datasets`) are mapped to force and response channels by their nodes and
directions, checked to agree in length and sample interval within an impact, and grouped into impacts by load
case (docs/contracts.md); a file whose load cases repeat per channel (some exporters leave them 0) is grouped
by the order of the records instead. The sample rate is the roundest one the header's digits allow.
"""

from __future__ import annotations

import math
import re
from collections import Counter, defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from labctl.errors import InputError
from labctl.processing.npz import ImpactSet
from labctl.uff import mapping as m
from labctl.uff.datasets import Header, UffFile
from labctl.uff.manifest import format_load_cases

STEP_ID = re.compile(r"(series \d+ run \d+ step \d+) impact \d+")  # id2 of a labctl export


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
