"""The import manifest: a CSV that gives each load step of UFF data its load, repetition and specimen.

One row per load step. Columns (units in the names): ``file`` (the UFF file, relative to the manifest; may be
left out when one file is imported), ``load_cases`` (its impacts, e.g. ``1-3`` or ``4;5;6``; default: all),
``load_n`` (load per roller), ``repetition``, and optionally ``step``, ``knob_angle_deg``, ``roller_type``,
``rail_ra_um``. Every error names the file, the row and the column.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

from labctl.data.csvfile import read_csv_records
from labctl.data.schema import MAX_RA_UM
from labctl.errors import InputError

MANIFEST_COLUMNS = ("file", "load_cases", "load_n", "repetition", "step", "knob_angle_deg", "roller_type",
                    "rail_ra_um")
REQUIRED = ("load_n", "repetition")


@dataclass(frozen=True)
class ManifestRow:
    """One load step of imported data (SI units)."""

    line: int
    file: str | None
    load_cases: tuple[int, ...] | None
    load_n: float
    repetition: int
    step: int | None = None
    knob_angle_deg: float = math.nan
    roller_type: int | None = None
    rail_ra_m: float | None = None


def parse_load_cases(text: str) -> tuple[int, ...]:
    """``1-3;7`` → (1, 2, 3, 7); separators ``;``, space or ``|``; ranges inclusive."""
    out: list[int] = []
    for part in (p for p in re.split(r"[;\s|]+", text.strip()) if p):
        m = re.fullmatch(r"(\d+)(?:-(\d+))?", part)
        if not m or (m.group(2) and int(m.group(2)) < int(m.group(1))):
            raise ValueError(part)
        lo = int(m.group(1))
        out.extend(range(lo, int(m.group(2) or lo) + 1))
    if not out or len(set(out)) != len(out):
        raise ValueError(text)
    return tuple(out)


def format_load_cases(ids: list[int]) -> str:
    """(1, 2, 3, 7) → ``1-3;7``."""
    runs: list[list[int]] = []
    for i in sorted(ids):
        if runs and runs[-1][1] == i - 1:
            runs[-1][1] = i
        else:
            runs.append([i, i])
    return ";".join(str(a) if a == b else f"{a}-{b}" for a, b in runs)


def _cell(path: Path, line: int, column: str, text: str, kind: type, expected: str, *, low: float = 0.0,
          strict: bool = True, high: float = math.inf) -> float | int:
    where = f"{path}: row {line}, column {column}"
    try:
        value = kind(float(text)) if kind is float else int(text)
    except ValueError:
        raise InputError(f"{where}: {text!r} is not {expected}") from None
    if not math.isfinite(value) or (value <= low if strict else value < low) or value > high:
        raise InputError(f"{where}: {text!r} is not {expected}")
    return value


def _row(path: Path, line: int, rec: dict[str, str]) -> ManifestRow:
    def get(col: str) -> str:
        return (rec.get(col) or "").strip()

    for col in REQUIRED:
        if not get(col):
            raise InputError(f"{path}: row {line}, column {col}: empty, expected "
                             + ("a positive load per roller in N" if col == "load_n" else "a repetition number"))
    cases = None
    if get("load_cases"):
        try:
            cases = parse_load_cases(get("load_cases"))
        except ValueError:
            raise InputError(f"{path}: row {line}, column load_cases: {get('load_cases')!r} is not a list of load "
                             "case numbers such as '1-3' or '4;5;6'") from None
    return ManifestRow(
        line=line, file=get("file") or None, load_cases=cases,
        load_n=float(_cell(path, line, "load_n", get("load_n"), float, "a positive load per roller in N")),
        repetition=int(_cell(path, line, "repetition", get("repetition"), int, "a repetition number ≥ 1")),
        step=int(_cell(path, line, "step", get("step"), int, "a step number ≥ 1")) if get("step") else None,
        knob_angle_deg=(float(_cell(path, line, "knob_angle_deg", get("knob_angle_deg"), float,
                                    "a knob angle in degrees", low=-math.inf, strict=False))
                        if get("knob_angle_deg") and get("knob_angle_deg").lower() != "nan" else math.nan),
        roller_type=(int(_cell(path, line, "roller_type", get("roller_type"), int, "a roller type number"))
                     if get("roller_type") else None),
        rail_ra_m=(float(_cell(path, line, "rail_ra_um", get("rail_ra_um"), float,
                               f"a rail Ra in [0, {MAX_RA_UM:g}] µm", strict=False, high=MAX_RA_UM)) * 1e-6
                   if get("rail_ra_um") else None),
    )


def read_manifest(path: str | Path) -> list[ManifestRow]:
    """Parse and check a manifest; steps of one repetition must be distinct."""
    p = Path(path)
    layout = f"a manifest has {', '.join(MANIFEST_COLUMNS)}; load_n and repetition are required"
    records = read_csv_records(p, what="manifest", required=REQUIRED, allowed=MANIFEST_COLUMNS, layout=layout)
    rows = [_row(p, line, rec) for line, rec in records]
    if not rows:
        raise InputError(f"{p}: no rows (expected one row per load step under the header)")
    return rows
