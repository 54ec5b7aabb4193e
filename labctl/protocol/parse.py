"""Read and validate protocol TOML files; every error names the file, the key, the value and what was expected."""

from __future__ import annotations

import difflib
import tomllib
from dataclasses import fields
from importlib import resources
from pathlib import Path
from typing import Any

from labctl.errors import InputError
from labctl.physics import materials, rollers
from labctl.physics.world import to_si
from labctl.processing import CheckConfig
from labctl.protocol.model import (
    AcquisitionSpec,
    LoadingSpec,
    Protocol,
    RepetitionSpec,
    SpecimenSpec,
    c0_cap_n,
)

TOP_KEYS = {"protocol", "specimen", "specimens", "loading", "acquisition", "repetitions", "checks"}
SPECIMEN_KEYS = {"kind", "label", "roller_type", "ball_diameter_mm", "ball_material", "rail_material", "rail_ra_um",
                 "max_load_n", "knob_step_deg"}
# the impact checks' thresholds, with times in ms at this edge (pulse_width_min_ms, …)
CHECK_KEYS = {f.name[:-2] + "_ms" if f.name.endswith("_s") else f.name for f in fields(CheckConfig)}


class _Where:
    """Builds error messages of the form ``file: [table].key = value: expected ...``."""

    def __init__(self, path: str, table: str) -> None:
        self.path, self.table = path, table

    def fail(self, key: str, value: Any, expected: str) -> InputError:
        return InputError(f"{self.path}: [{self.table}].{key} = {value!r}: expected {expected}")

    def unknown(self, key: str, valid: set[str]) -> InputError:
        close = difflib.get_close_matches(key, sorted(valid), n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        keys = ", ".join(sorted(valid))
        return InputError(f"{self.path}: [{self.table}] unknown key '{key}'{hint}; valid keys: {keys}")


def _check_keys(table: dict[str, Any], valid: set[str], where: _Where) -> None:
    for key in table:
        if key not in valid:
            raise where.unknown(key, valid)


def _number(table: dict[str, Any], key: str, default: float, where: _Where, *, lo: float | None = None,
            hi: float | None = None, lo_open: bool = False, integer: bool = False) -> Any:
    value = table.get(key, default)
    kind_ok = isinstance(value, int) if integer else isinstance(value, int | float)
    if isinstance(value, bool) or not kind_ok:
        raise where.fail(key, value, "an integer" if integer else "a number")
    bad_lo = lo is not None and (value <= lo if lo_open else value < lo)
    bad_hi = hi is not None and value > hi
    if bad_lo or bad_hi:
        span = f"{'>' if lo_open else '≥'} {lo:g}" if lo is not None else ""
        span += (" and " if span and hi is not None else "") + (f"≤ {hi:g}" if hi is not None else "")
        raise where.fail(key, value, f"a number {span}")
    return int(value) if integer else float(value)


def _table(doc: dict[str, Any], key: str, path: str) -> dict[str, Any]:
    value = doc.get(key, {})
    if not isinstance(value, dict):
        raise InputError(f"{path}: [{key}] must be a table, got {type(value).__name__}")
    return value


def _loading(doc: dict[str, Any], path: str) -> LoadingSpec:
    t, w = _table(doc, "loading", path), _Where(path, "loading")
    _check_keys(t, {f.name for f in fields(LoadingSpec)}, w)
    c0_length = t.get("c0_length", "total")
    if c0_length not in ("total", "contact"):
        raise w.fail("c0_length", c0_length, "'total' (L_r) or 'contact' (L_we)")
    return LoadingSpec(
        knob_step_deg=_number(t, "knob_step_deg", 180.0, w, lo=0, hi=3600, lo_open=True),
        max_load_fraction_c0=_number(t, "max_load_fraction_c0", 0.30, w, lo=0, hi=1.0, lo_open=True),
        c0_length=c0_length,
        max_steps=_number(t, "max_steps", 60, w, lo=1, hi=1000, integer=True),
        settle_timeout_s=_number(t, "settle_timeout_s", 30.0, w, lo=0, lo_open=True),
        settle_poll_s=_number(t, "settle_poll_s", 0.1, w, lo=0),
        load_tolerance_fraction=_number(t, "load_tolerance_fraction", 0.05, w, lo=0, hi=1, lo_open=True),
    )


def _acquisition(doc: dict[str, Any], path: str) -> AcquisitionSpec:
    t, w = _table(doc, "acquisition", path), _Where(path, "acquisition")
    _check_keys(t, {f.name for f in fields(AcquisitionSpec)}, w)
    samples = _number(t, "samples", 65536, w, lo=256, hi=2**24, integer=True)
    return AcquisitionSpec(
        sample_rate_hz=_number(t, "sample_rate_hz", 20480.0, w, lo=1000, hi=1e6),
        samples=samples,
        pretrigger_samples=_number(t, "pretrigger_samples", 256, w, lo=0, hi=samples // 2, integer=True),
        trigger_level_n=_number(t, "trigger_level_n", 20.0, w, lo=0, lo_open=True),
        impacts_per_step=_number(t, "impacts_per_step", 3, w, lo=1, hi=100, integer=True),
        max_rehits=_number(t, "max_rehits", 5, w, lo=0, hi=100, integer=True),
        timeout_s=_number(t, "timeout_s", 60.0, w, lo=0, lo_open=True),
        retries=_number(t, "retries", 2, w, lo=0, hi=20, integer=True),
    )


def _repetitions(doc: dict[str, Any], path: str) -> RepetitionSpec:
    t, w = _table(doc, "repetitions", path), _Where(path, "repetitions")
    _check_keys(t, {f.name for f in fields(RepetitionSpec)}, w)
    return RepetitionSpec(count=_number(t, "count", 3, w, lo=1, hi=1000, integer=True),
                          rotate_rollers_deg=_number(t, "rotate_rollers_deg", 5.0, w, lo=0, hi=180))


def _specimen(t: dict[str, Any], where: _Where, loading: LoadingSpec) -> SpecimenSpec:
    _check_keys(t, SPECIMEN_KEYS, where)
    kind = t.get("kind", "roller")
    if kind not in ("roller", "ball"):
        raise where.fail("kind", kind, "'roller' or 'ball'")
    known_materials = materials()
    for key in ("rail_material", "ball_material"):
        if key in t and t[key] not in known_materials:
            raise where.fail(key, t[key], f"a catalogue material ({', '.join(sorted(known_materials))})")
    rail_material = t.get("rail_material", "1.3505")
    rail_ra_m = _number(t, "rail_ra_um", 0.2, where, lo=0, hi=50) * 1e-6
    step = _number(t, "knob_step_deg", loading.knob_step_deg, where, lo=0, hi=3600, lo_open=True)
    roller_type = ball_d = None
    if kind == "roller":
        if "roller_type" not in t:
            raise InputError(f"{where.path}: [{where.table}] missing key 'roller_type' (a Table 1 type, 1-9)")
        roller_type = _number(t, "roller_type", 0, where, integer=True)
        if roller_type not in rollers():
            raise where.fail("roller_type", roller_type, f"a catalogue type ({', '.join(map(str, sorted(rollers())))})")
        cap = c0_cap_n("roller", roller_type, rail_material, loading)
        assert cap is not None
        max_load = _number(t, "max_load_n", cap, where, lo=0, lo_open=True)
        if max_load > cap * (1 + 1e-9):
            raise where.fail("max_load_n", max_load, f"at most the C0 cap {cap:.1f} N "
                             f"({loading.max_load_fraction_c0:g} × C0 of roller type {roller_type})")
        label = t.get("label", f"roller type {roller_type}")
    else:
        if "ball_diameter_mm" not in t:
            raise InputError(f"{where.path}: [{where.table}] missing key 'ball_diameter_mm'")
        ball_d = _number(t, "ball_diameter_mm", 0, where, lo=0, hi=100, lo_open=True) * 1e-3
        if "max_load_n" not in t:
            raise InputError(f"{where.path}: [{where.table}] missing key 'max_load_n' (balls have no C0 cap here)")
        max_load = _number(t, "max_load_n", 0, where, lo=0, lo_open=True)
        label = t.get("label", f"ball {ball_d * 1e3:g} mm")
    return SpecimenSpec(kind=kind, label=str(label), roller_type=roller_type, ball_diameter_m=ball_d,
                        ball_material=t.get("ball_material", "1.3505"), rail_material=rail_material,
                        rail_ra_m=rail_ra_m, max_load_n=max_load, knob_step_deg=step)


def _checks(doc: dict[str, Any], path: str) -> CheckConfig:
    """The impact checks' thresholds, overridden where the protocol's ``[checks]`` table says so."""
    t, w = _table(doc, "checks", path), _Where(path, "checks")
    _check_keys(t, CHECK_KEYS, w)
    try:
        return CheckConfig(**dict(to_si(k, _number(t, k, 0, w, lo=0)) for k in t))
    except ValueError as exc:
        raise InputError(f"{path}: [checks] {exc}") from None


def parse_protocol(text: str, path: str = "<protocol>") -> Protocol:
    """Validate protocol TOML text."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML ({exc})") from None
    for key in doc:
        if key not in TOP_KEYS:
            raise _Where(path, "top level").unknown(key, TOP_KEYS)
    head = _table(doc, "protocol", path)
    _check_keys(head, {"name", "description", "version"}, _Where(path, "protocol"))
    loading = _loading(doc, path)
    if "specimen" in doc and "specimens" in doc:
        raise InputError(f"{path}: give either [specimen] or [[specimens]], not both")
    raw = doc.get("specimens", [doc.get("specimen")] if "specimen" in doc else None)
    if not raw or not isinstance(raw, list) or not all(isinstance(s, dict) for s in raw):
        raise InputError(f"{path}: missing [specimen] table (or [[specimens]] array) naming what is tested")
    specimens = tuple(
        _specimen(s, _Where(path, "specimen" if "specimen" in doc else f"specimens[{i}]"), loading)
        for i, s in enumerate(raw)
    )
    checks = _checks(doc, path)
    return Protocol(
        name=str(head.get("name", Path(path).stem)),
        description=str(head.get("description", "")),
        specimens=specimens,
        loading=loading,
        acquisition=_acquisition(doc, path),
        repetitions=_repetitions(doc, path),
        checks=checks,
        source_path=path,
        source_text=text,
    )


def shipped_protocols() -> dict[str, Path]:
    """Protocol files shipped with labctl, by file stem."""
    root = resources.files("labctl.protocols")
    return {Path(p.name).stem: Path(str(p)) for p in root.iterdir() if p.name.endswith(".toml")}


def resolve_protocol_path(name_or_path: str | Path) -> Path:
    """A path as given if it exists; otherwise a shipped protocol of that name (``quick_check``)."""
    p = Path(name_or_path)
    if p.is_file():
        return p
    shipped = shipped_protocols()
    key = p.stem if p.suffix == ".toml" else p.name
    if key in shipped and (len(p.parts) == 1 or p.parent.name == "protocols"):
        return shipped[key]
    raise InputError(f"{p}: protocol file not found (shipped protocols: {', '.join(sorted(shipped))})")


def load_protocol(name_or_path: str | Path) -> Protocol:
    """Read and validate a protocol file (or a shipped protocol by name)."""
    path = resolve_protocol_path(name_or_path)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a UTF-8 text file") from None
    return parse_protocol(text, str(name_or_path))
