"""Read-only queries of the archive catalogue: a WHERE clause over a documented view, and its stiffness table.

The clause runs on a connection opened read-only whose authorizer allows nothing but reading the catalogue
(no writes, ATTACH, PRAGMA or schema changes), so a query can never alter the archive.
"""

from __future__ import annotations

import re
import sqlite3
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from labctl.archive.catalogue import VIEWS, check_catalogue
from labctl.errors import InputError
from labctl.stiffness_table import StiffnessPoint

_ALLOWED = {sqlite3.SQLITE_SELECT, sqlite3.SQLITE_READ, sqlite3.SQLITE_FUNCTION}
_CASE_FIELDS = ("diameter_mm", "contact_length_mm", "rail_ra_um", "roller_type", "roller_length_mm", "material",
                "youngs_modulus_gpa", "poisson_ratio", "hardness_hrc", "rail_material")


@dataclass(frozen=True)
class QueryResult:
    """Rows of a view matching a clause, as dictionaries in the view's column order."""

    view: str
    where: str
    columns: tuple[str, ...]
    rows: list[dict[str, Any]]


def _authorize(action: int, arg1: str | None, arg2: str | None, db: str | None, trigger: str | None) -> int:
    return sqlite3.SQLITE_OK if action in _ALLOWED else sqlite3.SQLITE_DENY


def read_only_connection(db: str | Path) -> sqlite3.Connection:
    """A connection to the catalogue that can only read (for Python users' own SQL over the views)."""
    p = Path(db)
    if not p.is_file():
        raise InputError(f"{p}: no archive catalogue (build one with 'labctl archive index DIR --db {p}')")
    check_catalogue(p)
    conn = sqlite3.connect(f"{p.resolve().as_uri()}?mode=ro", uri=True)
    conn.set_authorizer(_authorize)
    return conn


def query(db: str | Path, where: str = "", *, view: str = "steps") -> QueryResult:
    """Rows of ``view`` (``steps`` or ``campaigns``) for which the SQL expression ``where`` holds (all if empty)."""
    if view not in VIEWS:
        raise InputError(f"unknown view {view!r}: expected one of {', '.join(VIEWS)}")
    clause = where.strip().rstrip(";") or "1"
    columns = VIEWS[view]
    sql = f"SELECT {', '.join(columns)} FROM {view} WHERE ({clause}) ORDER BY path, " + (
        "series, run, step" if view == "steps" else "created_utc")
    conn = read_only_connection(db)
    try:
        rows = [dict(zip(columns, r, strict=True)) for r in conn.execute(sql)]
    except sqlite3.DatabaseError as exc:
        raise InputError(_explain(where, view, str(exc))) from None
    finally:
        conn.close()
    return QueryResult(view, where, columns, rows)


def _explain(where: str, view: str, message: str) -> str:
    bad = re.match(r"no such column: (\S+)", message)
    if bad:
        return (f"query {where!r}: no column {bad.group(1)!r} in view {view}; columns are "
                f"{', '.join(VIEWS[view])}")
    if "not authorized" in message:
        return f"query {where!r}: only reading the catalogue is allowed"
    return f"query {where!r}: {message}"


def stiffness_points(rows: list[dict[str, Any]]) -> tuple[list[StiffnessPoint], int]:
    """The stiffness table of ``steps`` rows, and how many rows had no identified roller stiffness.

    ``repetition`` numbers each (campaign file, series, run) of one contact case 1, 2, … in path order, so
    repetitions from different campaigns of the same roller stay apart for the noise estimate.
    """
    points: list[StiffnessPoint] = []
    reps: dict[tuple[Any, ...], dict[tuple[Any, ...], int]] = {}
    left_out = 0
    for r in rows:
        need = (r.get("diameter_mm"), r.get("contact_length_mm"), r.get("rail_ra_um"), r.get("load_n"),
                r.get("stiffness_n_per_m"))
        if any(v is None for v in need) or r["load_n"] <= 0 or r["stiffness_n_per_m"] <= 0:
            left_out += 1
            continue
        case = tuple(r.get(f) for f in _CASE_FIELDS)
        seen = reps.setdefault(case, {})
        rep = seen.setdefault((r["path"], r["series"], r["run"]), len(seen) + 1)
        points.append(StiffnessPoint(
            diameter_m=r["diameter_mm"] * 1e-3, contact_length_m=r["contact_length_mm"] * 1e-3,
            rail_ra_m=r["rail_ra_um"] * 1e-6, load_n=r["load_n"], stiffness_n_per_m=r["stiffness_n_per_m"],
            roller_type=r.get("roller_type"),
            roller_length_m=None if r.get("roller_length_mm") is None else r["roller_length_mm"] * 1e-3,
            material=r.get("material"),
            youngs_modulus_pa=None if r.get("youngs_modulus_gpa") is None else r["youngs_modulus_gpa"] * 1e9,
            poisson_ratio=r.get("poisson_ratio"), hardness_hrc=r.get("hardness_hrc"), repetition=rep,
            rail_material=r.get("rail_material")))
    return points, left_out
