"""A group of repetition curves from campaign files, stiffness-table CSVs or an archive query.

A curve is one repetition (one seating of the rollers): its stiffness at each load step. Curves are the
replicates of the comparison: their scatter is the repetition scatter the difference must exceed.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from labctl.errors import InputError

MIN_POINTS = 2


@dataclass(frozen=True)
class Curve:
    """One repetition's stiffness against load (SI), with where it came from."""

    source: str
    """The file (and series/run, or CSV case and repetition) the curve was read from."""
    campaign: str
    """The campaign (file, and series) it belongs to: curves of one campaign share its day, rig and specimen."""
    load_n: np.ndarray
    """Load per roller at each identified step, N, increasing."""
    stiffness_n_per_m: np.ndarray
    """Roller stiffness at each of those loads, N/m."""


def _curve(source: str, campaign: str, load_n: Iterable[float], stiffness: Iterable[float]) -> Curve | None:
    f = np.asarray(list(load_n), dtype=float)
    k = np.asarray(list(stiffness), dtype=float)
    keep = np.isfinite(f) & np.isfinite(k) & (f > 0) & (k > 0)
    f, k = f[keep], k[keep]
    if f.size < MIN_POINTS:
        return None
    order = np.argsort(f, kind="stable")
    return Curve(source, campaign, f[order], k[order])


def _from_campaign(path: Path) -> list[Curve]:
    from labctl.storage import CampaignReader

    with CampaignReader(path) as reader:
        found = reader.curves()
    out = []
    for c in found:
        curve = _curve(f"{path.name} series {c.series} run {c.run} ({c.specimen})", f"{path} series {c.series}",
                       c.load_n, c.stiffness_n_per_m)
        if curve is not None:
            out.append(curve)
    return out


def _from_csv(path: Path) -> list[Curve]:
    from labctl.stiffness_table import read_stiffness_table

    groups: dict[tuple, list] = {}
    for p in read_stiffness_table(path):
        case = (p.roller_type, round(p.diameter_m, 9), round(p.contact_length_m, 9), round(p.rail_ra_m, 12),
                p.material, p.rail_material, p.repetition)
        groups.setdefault(case, []).append(p)
    out = []
    for case, pts in groups.items():
        label = f"type {case[0]}" if case[0] is not None else f"D {case[1] * 1e3:g} mm"
        rep = f" repetition {case[-1]}" if case[-1] is not None else ""
        curve = _curve(f"{path.name} {label}{rep}", f"{path} {label}", (p.load_n for p in pts),
                       (p.stiffness_n_per_m for p in pts))
        if curve is not None:
            out.append(curve)
    return out


def _from_query(db: Path, where: str) -> list[Curve]:
    from labctl.archive.query import query

    rows = query(db, where).rows
    groups: dict[tuple, list] = {}
    for r in rows:
        if r.get("load_n") is None or r.get("stiffness_n_per_m") is None:
            continue
        groups.setdefault((r["path"], r["series"], r["run"]), []).append(r)
    out = []
    for (path, series, run), rs in sorted(groups.items()):
        curve = _curve(f"{Path(path).name} series {series} run {run}", f"{path} series {series}",
                       (r["load_n"] for r in rs), (r["stiffness_n_per_m"] for r in rs))
        if curve is not None:
            out.append(curve)
    return out


def _paths(spec: str) -> list[Path] | None:
    """The files a group names (comma-separated files or folders), or None when it names no existing path."""
    items = [s.strip() for s in spec.split(",") if s.strip()]
    if not items or not all(Path(s).exists() for s in items):
        return None
    files: list[Path] = []
    for s in items:
        p = Path(s)
        files.extend(sorted(p.rglob("*.h5")) if p.is_dir() else [p])
    return files


def load_group(spec: str, *, db: str | Path | None = None, name: str = "group") -> list[Curve]:
    """The curves of one group: ``spec`` names campaign files (``.h5``), stiffness tables (``.csv``) or folders
    of campaign files, comma-separated; anything else is a query over the archive catalogue ``db``."""
    files = _paths(spec)
    curves: list[Curve] = []
    if files is not None:
        if not files:
            raise InputError(f"{name} {spec!r}: no campaign files (*.h5) in that folder")
        if len(set(f.resolve() for f in files)) != len(files):
            raise InputError(f"{name} {spec!r}: a file is named twice; each campaign counts once")
        for f in files:
            curves.extend(_from_csv(f) if f.suffix.lower() == ".csv" else _from_campaign(f))
    elif db is None or not Path(db).is_file():
        raise InputError(f"{name} {spec!r}: no such file or folder (an archive query needs --db CATALOGUE, "
                         f"{'not found: ' + str(db) if db else 'not given'})")
    else:
        curves = _from_query(Path(db), spec)
    if not curves:
        raise InputError(f"{name} {spec!r}: no repetition with {MIN_POINTS} or more identified steps")
    return curves


def overlap(curves: Sequence[Curve]) -> tuple[float, float]:
    """The load range every curve covers (N)."""
    return max(float(c.load_n[0]) for c in curves), min(float(c.load_n[-1]) for c in curves)
