"""The archive catalogue: an SQLite file describing every campaign file of a lab, updated incrementally.

A campaign is read again only when its path, size, modification time, root-attribute hash or its results
sidecar changed. The documented views ``campaigns`` and ``steps`` (docs/archive.md) are the contract; the
tables behind them are not.
"""

from __future__ import annotations

import hashlib
import math
import sqlite3
import tomllib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from labctl.archive.source import CampaignRecord, read_campaign, root_sha256
from labctl.errors import InputError
from labctl.storage.records import result_from_mapping
from labctl.storage.results import read_results, results_path
from labctl.storage.specimen import SpecimenRecord
from labctl.storage.writer import utc_now

SCHEMA_VERSION = 2  # 2: the specimen's conditions (lubrication, orientation, measured roughness and form)
CAMPAIGN_GLOB = "*.h5"

_TABLES = """
CREATE TABLE IF NOT EXISTS campaign_file (
    id INTEGER PRIMARY KEY, path TEXT UNIQUE NOT NULL, file_name TEXT NOT NULL,
    size_bytes INTEGER NOT NULL, mtime_ns INTEGER NOT NULL, root_sha256 TEXT NOT NULL,
    results_size INTEGER, results_mtime_ns INTEGER, indexed_utc TEXT NOT NULL, error TEXT NOT NULL,
    format_version INTEGER, software_version TEXT, created_utc TEXT, resumed_utc TEXT, status_utc TEXT,
    status TEXT, status_message TEXT, backend TEXT, seed INTEGER, world_file TEXT,
    protocol_name TEXT, protocol_version INTEGER, protocol_description TEXT, rig_name TEXT, rig_sha256 TEXT,
    processed_utc TEXT, processed_software_version TEXT, processed_rig_name TEXT, processed_rig_sha256 TEXT,
    results_current INTEGER, n_series INTEGER, n_runs INTEGER, n_steps INTEGER, n_identified INTEGER);
CREATE TABLE IF NOT EXISTS specimen_row (
    campaign_id INTEGER NOT NULL REFERENCES campaign_file(id) ON DELETE CASCADE, series INTEGER NOT NULL,
    kind TEXT, label TEXT, roller_type INTEGER, ball_diameter_mm REAL, diameter_mm REAL, contact_length_mm REAL,
    roller_length_mm REAL, material TEXT, youngs_modulus_gpa REAL, poisson_ratio REAL, hardness_hrc REAL,
    rail_material TEXT, rail_ra_um REAL, max_load_n REAL, knob_step_deg REAL,
    lubrication TEXT, lubricant TEXT, orientation_deg REAL, roller_ra_measured_um REAL, rail_ra_measured_um REAL,
    roundness_um REAL, cylindricity_um REAL,
    PRIMARY KEY (campaign_id, series));
CREATE TABLE IF NOT EXISTS step_row (
    campaign_id INTEGER NOT NULL REFERENCES campaign_file(id) ON DELETE CASCADE, series INTEGER NOT NULL,
    run INTEGER NOT NULL, step INTEGER NOT NULL, run_complete INTEGER, step_complete INTEGER,
    knob_angle_deg REAL, expected_load_n REAL, load_n REAL, load_total_n REAL, impacts INTEGER,
    accepted_impacts INTEGER, identified INTEGER NOT NULL, result_source TEXT, error TEXT,
    bounce_hz REAL, bounce_hz_std REAL, bounce_damping_ratio REAL, tilt_a_hz REAL, tilt_b_hz REAL,
    stiffness_n_per_m REAL, stiffness_std_n_per_m REAL, coherence_at_bounce REAL,
    PRIMARY KEY (campaign_id, series, run, step));
CREATE TABLE IF NOT EXISTS catalogue_info (key TEXT PRIMARY KEY, value TEXT);
"""

CAMPAIGN_COLUMNS = (
    "path", "file_name", "size_bytes", "error", "status", "status_message", "created_utc", "resumed_utc",
    "status_utc", "software_version", "format_version", "backend", "seed", "world_file", "protocol_name",
    "protocol_version", "protocol_description", "rig_name", "rig_sha256", "root_sha256", "processed_utc",
    "processed_software_version", "processed_rig_name", "processed_rig_sha256", "results_current", "n_series",
    "n_runs", "n_steps", "n_identified", "indexed_utc")
CONDITION_COLUMNS = ("lubrication", "lubricant", "orientation_deg", "roller_ra_measured_um", "rail_ra_measured_um",
                     "roundness_um", "cylindricity_um")
SPECIMEN_COLUMNS = (
    "series", "kind", "label", "roller_type", "ball_diameter_mm", "diameter_mm", "contact_length_mm",
    "roller_length_mm", "material", "youngs_modulus_gpa", "poisson_ratio", "hardness_hrc", "rail_material",
    "rail_ra_um", "max_load_n", "knob_step_deg", *CONDITION_COLUMNS)
STEP_COLUMNS = (
    "run", "step", "run_complete", "step_complete", "knob_angle_deg", "expected_load_n", "load_n", "load_total_n",
    "impacts", "accepted_impacts", "identified", "result_source", "error", "bounce_hz", "bounce_hz_std",
    "bounce_damping_ratio", "tilt_a_hz", "tilt_b_hz", "stiffness_n_per_m", "stiffness_std_n_per_m",
    "coherence_at_bounce")
_STEP_VIEW_CAMPAIGN = ("path", "file_name", "status", "created_utc", "software_version", "backend", "seed",
                       "protocol_name", "protocol_version", "rig_name", "processed_utc",
                       "processed_software_version", "results_current")

_VIEWS = (
    "CREATE VIEW IF NOT EXISTS campaigns AS SELECT "
    + ", ".join(f"c.{c}" for c in CAMPAIGN_COLUMNS) + " FROM campaign_file c;\n"
    "CREATE VIEW IF NOT EXISTS steps AS SELECT "
    + ", ".join([*(f"c.{c}" for c in _STEP_VIEW_CAMPAIGN), *(f"s.{c}" for c in SPECIMEN_COLUMNS),
                 *(f"t.{c}" for c in STEP_COLUMNS)])
    + " FROM step_row t JOIN campaign_file c ON c.id = t.campaign_id"
      " JOIN specimen_row s ON s.campaign_id = t.campaign_id AND s.series = t.series;\n"
)
VIEWS: dict[str, tuple[str, ...]] = {
    "steps": (*_STEP_VIEW_CAMPAIGN, *SPECIMEN_COLUMNS, *STEP_COLUMNS),
    "campaigns": CAMPAIGN_COLUMNS,
}


def edge(value: Any, exponent: int = 0) -> float | None:
    """An SI value in the catalogue's unit (×10^exponent), to 12 significant digits so ``rail_ra_um = 0.2``
    matches; None when absent or not finite."""
    if value is None or isinstance(value, str | bool | list | dict):
        return None
    v = float(value)
    return float(f"{v * 10.0 ** exponent:.12g}") if math.isfinite(v) else None


def _int(value: Any) -> int | None:
    try:
        return None if value is None or value == "" else int(value)
    except (TypeError, ValueError):
        return None


@dataclass
class IndexReport:
    """What one ``index`` pass did."""

    new: list[str] = field(default_factory=list)
    updated: list[str] = field(default_factory=list)
    unchanged: list[str] = field(default_factory=list)
    removed: list[str] = field(default_factory=list)
    failed: list[tuple[str, str]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"new": self.new, "updated": self.updated, "unchanged": len(self.unchanged),
                "removed": self.removed, "failed": [{"path": p, "error": e} for p, e in self.failed]}


def campaign_files(paths: Iterable[str | Path]) -> list[Path]:
    """Campaign files named directly or found (``*.h5``, recursively) under the given folders, sorted."""
    found: set[Path] = set()
    for item in paths:
        p = Path(item)
        if p.is_dir():
            found.update(f.resolve() for f in p.rglob(CAMPAIGN_GLOB) if f.is_file())
        elif p.is_file():
            found.add(p.resolve())
        else:
            raise InputError(f"{p}: no such file or folder")
    return sorted(found)


def check_catalogue(db: str | Path) -> None:
    """Refuse (InputError) an existing file that is not a labctl catalogue, before anything is written to it.

    A catalogue is an SQLite file whose ``catalogue_info`` table holds ``schema_version``; an empty file is
    a new catalogue. Another application's database, an HDF5 file or a text file is left untouched."""
    p = Path(db)
    if not p.exists():
        return
    if p.is_dir():
        raise InputError(f"--db {p}: is a folder; expected an archive catalogue file")
    try:
        size = p.stat().st_size
        with p.open("rb") as fh:
            head = fh.read(16)
    except OSError as exc:
        raise InputError(f"--db {p}: cannot read the catalogue ({exc.strerror or exc})") from None
    if size == 0:
        return
    if head != b"SQLite format 3\x00":
        raise InputError(f"--db {p}: not an SQLite file, so not a labctl archive catalogue; choose another --db")
    try:
        ro = sqlite3.connect(f"{p.resolve().as_uri()}?mode=ro", uri=True)
        try:
            names = {r[0] for r in ro.execute("SELECT name FROM sqlite_master WHERE type IN ('table', 'view')")}
            version = (ro.execute("SELECT value FROM catalogue_info WHERE key = 'schema_version'").fetchone()
                       if "catalogue_info" in names else None)
        finally:
            ro.close()
    except sqlite3.DatabaseError as exc:
        raise InputError(f"--db {p}: not a usable archive catalogue ({exc})") from None
    if version is None:
        raise InputError(f"--db {p}: an SQLite database of another application (no labctl catalogue_info "
                         "table); it was not changed; choose another --db")
    if not str(version[0]).isdigit() or not 1 <= int(version[0]) <= SCHEMA_VERSION:  # older ones are upgraded
        raise InputError(f"--db {p}: catalogue schema version {version[0]}, this labctl writes "
                         f"{SCHEMA_VERSION} (and upgrades older ones); it was not changed")


def connect(db: str | Path) -> sqlite3.Connection:
    """Open (creating if needed) a catalogue for writing; a file that is not a catalogue is refused first."""
    p = Path(db)
    check_catalogue(p)
    try:
        conn = sqlite3.connect(p)
        conn.execute("PRAGMA foreign_keys = ON")
        with conn:
            _upgrade(conn)
            conn.executescript(_TABLES + _VIEWS)
            conn.execute("INSERT OR IGNORE INTO catalogue_info VALUES ('schema_version', ?)", (str(SCHEMA_VERSION),))
    except sqlite3.DatabaseError as exc:
        raise InputError(f"{p}: not a usable archive catalogue ({exc})") from None
    return conn


def _upgrade(conn: sqlite3.Connection) -> None:
    """Bring an older labctl catalogue to this schema: version 1 lacked the conditions columns, so its views are
    rebuilt and every file is forgotten (the next ``index`` reads them all again, conditions included)."""
    row = conn.execute("SELECT name FROM sqlite_master WHERE type = 'table' AND name = 'catalogue_info'").fetchone()
    if row is None:
        return
    found = conn.execute("SELECT value FROM catalogue_info WHERE key = 'schema_version'").fetchone()
    if found is None or int(found[0]) >= SCHEMA_VERSION:
        return
    conn.executescript("DROP VIEW IF EXISTS steps; DROP VIEW IF EXISTS campaigns; DELETE FROM step_row; "
                       "DELETE FROM specimen_row; DELETE FROM campaign_file; DROP TABLE specimen_row;")
    conn.execute("UPDATE catalogue_info SET value = ? WHERE key = 'schema_version'", (str(SCHEMA_VERSION),))


@dataclass(frozen=True)
class _Stat:
    size: int
    mtime_ns: int
    results_size: int | None
    results_mtime_ns: int | None


def _stat(path: Path) -> _Stat:
    st = path.stat()
    rp = results_path(path)
    rs = rp.stat() if rp.is_file() else None
    return _Stat(st.st_size, st.st_mtime_ns, rs.st_size if rs else None, rs.st_mtime_ns if rs else None)


def index(db: str | Path, paths: Sequence[str | Path]) -> IndexReport:
    """Bring the catalogue up to date with the campaign files under ``paths``; unchanged files are not read."""
    files = campaign_files(paths)
    report = IndexReport()
    conn = connect(db)
    try:
        for path in files:
            _index_one(conn, path, report)
        roots = [Path(p).resolve() for p in paths if Path(p).is_dir()]
        seen = {str(p) for p in files}
        for (stored,) in conn.execute("SELECT path FROM campaign_file").fetchall():
            if stored not in seen and any(Path(stored).is_relative_to(r) for r in roots) and not Path(stored).exists():
                with conn:
                    conn.execute("DELETE FROM campaign_file WHERE path = ?", (stored,))
                report.removed.append(stored)
    finally:
        conn.close()
    return report


def _index_one(conn: sqlite3.Connection, path: Path, report: IndexReport) -> None:
    try:
        str(path).encode("utf-8")
    except UnicodeEncodeError:  # a name the catalogue (UTF-8 text) cannot hold: skipped, named, the rest indexed
        shown = str(path).encode("utf-8", "backslashreplace").decode("utf-8")
        report.failed.append((shown, f"{shown}: file name is not valid UTF-8; rename the file to catalogue it"))
        return
    st = _stat(path)
    row = conn.execute("SELECT size_bytes, mtime_ns, root_sha256, results_size, results_mtime_ns, error "
                       "FROM campaign_file WHERE path = ?", (str(path),)).fetchone()
    try:
        root, error = root_sha256(path), ""
    except Exception as exc:  # noqa: BLE001 — one unreadable file must not stop the index
        root, error = "", _message(path, exc)
    if row is not None and tuple(row[:5]) == (st.size, st.mtime_ns, root, st.results_size, st.results_mtime_ns):
        if row[5]:
            report.failed.append((str(path), row[5]))
        else:
            report.unchanged.append(str(path))
        return
    fields: dict[str, Any] = {}
    children: dict[str, list[dict[str, Any]]] = {}
    if not error:
        try:
            fields, children = _record_rows(read_campaign(path), st)
        except Exception as exc:  # noqa: BLE001 — a damaged campaign is catalogued with its error
            error = _message(path, exc)
    with conn:
        conn.execute("DELETE FROM campaign_file WHERE path = ?", (str(path),))
        base = {"path": str(path), "file_name": path.name, "size_bytes": st.size, "mtime_ns": st.mtime_ns,
                "root_sha256": root, "results_size": st.results_size, "results_mtime_ns": st.results_mtime_ns,
                "indexed_utc": utc_now(), "error": error, **fields}
        cid = _insert(conn, "campaign_file", base)
        for table, rows in children.items():
            for r in rows:
                _insert(conn, table, {"campaign_id": cid, **r})
    (report.failed.append((str(path), base["error"])) if base["error"]
     else (report.updated if row is not None else report.new).append(str(path)))


def _message(path: Path, exc: Exception) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if str(path) in text else f"{path}: {type(exc).__name__}: {text}"


def _insert(conn: sqlite3.Connection, table: str, row: dict[str, Any]) -> int:
    cur = conn.execute(f"INSERT INTO {table} ({', '.join(row)}) VALUES ({', '.join('?' * len(row))})",
                       tuple(row.values()))
    return int(cur.lastrowid or 0)


def _toml_field(text: str | None, table: str, key: str) -> Any:
    if not text:
        return None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        return None
    value = doc.get(table, {}).get(key) if table else doc.get(key)
    return value if isinstance(value, str | int | float) else None


def _specimen_row(series: int, sp: SpecimenRecord) -> dict[str, Any]:
    return {"series": series, "kind": sp.kind, "label": sp.label, "roller_type": _int(sp.roller_type),
            "ball_diameter_mm": edge(sp.ball_diameter_m, 3), "diameter_mm": edge(sp.diameter_m, 3),
            "contact_length_mm": edge(sp.contact_length_m, 3), "roller_length_mm": edge(sp.roller_length_m, 3),
            "material": sp.material, "youngs_modulus_gpa": edge(sp.youngs_modulus_pa, -9),
            "poisson_ratio": edge(sp.poisson_ratio), "hardness_hrc": edge(sp.hardness_hrc),
            "rail_material": sp.rail_material, "rail_ra_um": edge(sp.rail_ra_m, 6), "max_load_n": edge(sp.max_load_n),
            "knob_step_deg": edge(sp.knob_step_deg), "lubrication": sp.lubrication, "lubricant": sp.lubricant,
            "orientation_deg": edge(sp.orientation_deg), "roller_ra_measured_um": edge(sp.roller_ra_m, 6),
            "rail_ra_measured_um": edge(sp.rail_ra_measured_m, 6), "roundness_um": edge(sp.roundness_m, 6),
            "cylindricity_um": edge(sp.cylindricity_m, 6)}


def _result_columns(result: dict[str, Any] | None) -> dict[str, Any]:
    r = result_from_mapping({k: v for k, v in (result or {}).items() if v is not None})  # a sidecar's JSON, typed
    tilt = r.tilt_hz
    k = edge(r.roller_stiffness_n_per_m)
    return {"identified": int(k is not None and k > 0), "bounce_hz": edge(r.bounce_hz),
            "bounce_hz_std": edge(r.bounce_hz_std), "bounce_damping_ratio": edge(r.bounce_damping_ratio),
            "tilt_a_hz": edge(tilt[0]) if len(tilt) > 0 else None,
            "tilt_b_hz": edge(tilt[1]) if len(tilt) > 1 else None,
            "stiffness_n_per_m": k, "stiffness_std_n_per_m": edge(r.roller_stiffness_std_n_per_m),
            "coherence_at_bounce": edge(r.coherence_at_bounce)}


def _reprocessed_steps(record: CampaignRecord, st: _Stat) -> tuple[dict[str, Any] | None, bool]:
    """The sidecar document and whether it belongs to the campaign as it is now (same size and root hash)."""
    try:
        doc = read_results(record.path)
    except InputError:  # a damaged sidecar: show the results stored in the campaign file
        return {}, False
    if doc is None:
        return None, False
    src = doc.get("source", {})
    return doc, src.get("size_bytes") == st.size and src.get("root_sha256") == record.root_sha256


def _record_rows(record: CampaignRecord, st: _Stat) -> tuple[dict[str, Any], dict[str, list[dict[str, Any]]]]:
    """The campaign's catalogue fields and its specimen and step rows."""
    a = record.attrs
    doc, current = _reprocessed_steps(record, st)
    redone = {(s["series"], s["run"], s["step"]): s for s in doc.get("steps", [])} if doc and current else {}
    steps = []
    for s in record.steps:
        again = redone.get((s.series, s.run, s.step))
        if again is not None:
            res, source, error = again.get("result"), "reprocessed", again.get("error") or ""
        else:
            res = s.result
            source = "acquisition" if res else ""
            error = str(s.attrs.get("failed", "")) if not res else ""
        steps.append({"series": s.series, "run": s.run, "step": s.step, "run_complete": int(s.run_complete),
                      "step_complete": int(s.step_complete), "knob_angle_deg": edge(s.attrs.get("knob_angle_deg")),
                      "expected_load_n": edge(s.attrs.get("expected_load_n")), "load_n": edge(s.attrs.get("load_n")),
                      "load_total_n": edge(s.attrs.get("load_total_n")), "impacts": s.impacts,
                      "accepted_impacts": s.accepted_impacts, "result_source": source, "error": error,
                      **_result_columns(res)})
    children = {"specimen_row": [_specimen_row(k, v) for k, v in record.specimens.items()], "step_row": steps}
    desc = a.get("backend_description") if isinstance(a.get("backend_description"), dict) else {}
    rig = (doc or {}).get("rig", {})
    fields = {"format_version": _int(a.get("format_version")), "software_version": a.get("software_version"),
            "created_utc": a.get("created_utc"), "resumed_utc": a.get("resumed_utc"),
            "status_utc": a.get("status_utc"), "status": a.get("status"), "status_message": a.get("status_message"),
            "backend": a.get("backend"), "seed": _int(a.get("seed")), "world_file": desc.get("world_file"),
            "protocol_name": a.get("protocol_name"),
            "protocol_version": _int(_toml_field(record.protocol_text, "protocol", "version")),
            "protocol_description": _toml_field(record.protocol_text, "protocol", "description"),
            "rig_name": _toml_field(record.rig_text, "", "name"),
            "rig_sha256": hashlib.sha256(record.rig_text.encode()).hexdigest() if record.rig_text else None,
            "processed_utc": (doc or {}).get("processed_utc"),
            "processed_software_version": (doc or {}).get("software_version"),
            "processed_rig_name": rig.get("name"), "processed_rig_sha256": rig.get("sha256"),
            "results_current": None if doc is None else int(current),
            "n_series": len(record.specimens), "n_runs": len({(s.series, s.run) for s in record.steps}),
            "n_steps": len(steps), "n_identified": sum(r["identified"] for r in steps)}
    return fields, children
