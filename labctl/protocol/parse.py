"""Read and validate protocol TOML files through ``labctl.data.schema``: every error names the file, the table,
the key, the value and what was expected (the closest key for an unknown one)."""

from __future__ import annotations

from dataclasses import fields
from importlib import resources
from pathlib import Path
from typing import Any

from labctl.data.conditions import LUBRICATIONS, SpecimenConditions
from labctl.data.schema import (
    MAX_RA_UM,
    Anything,
    Integer,
    Number,
    Spec,
    Table,
    Tables,
    Text,
    Where,
    build,
    check_keys,
    parse_toml,
    read,
    value,
)
from labctl.data.units import edge_name
from labctl.errors import InputError
from labctl.physics import materials, rollers
from labctl.processing import CheckConfig
from labctl.protocol.model import (
    AcquisitionSpec,
    LoadingSpec,
    Protocol,
    RepetitionSpec,
    SpecimenSpec,
    c0_cap_n,
)
from labctl.protocol.static import parse_static

TOP_KEYS = {"protocol", "specimen", "specimens", "loading", "acquisition", "repetitions", "checks"}
TOP_KEYS |= {"static"}  # the static load–displacement method (labctl.protocol.static)
HEAD = {"name": Text(default=None), "description": Text(default=""), "version": Anything(default=None)}
LOADING: dict[str, Spec] = {
    "knob_step_deg": Number(gt=0, le=3600),
    "max_load_fraction_c0": Number(gt=0, le=1),
    "c0_length": Text({"total": "L_r", "contact": "L_we"}),
    "max_steps": Integer(1, 1000),
    "settle_timeout_s": Number(gt=0),
    "settle_poll_s": Number(ge=0),
    "load_tolerance_fraction": Number(gt=0, le=1),
    "load_source": Text(("load_cell", "springs")),
}
REPETITIONS: dict[str, Spec] = {"count": Integer(1, 1000), "rotate_rollers_deg": Number(ge=0, le=180)}
SPECIMEN_KEYS = {"kind", "label", "roller_type", "ball_diameter_mm", "ball_material", "rail_material", "rail_ra_um",
                 "max_load_n", "knob_step_deg", "conditions"}
# bounds of the impact checks that are fractions; every other threshold is a number ≥ 0
_CHECK_BOUNDS = {"overload_fraction": Number(gt=0, le=1), "double_hit_ratio": Number(gt=0, lt=1),
                 "min_coherence": Number(ge=0, le=1)}
# the impact checks' thresholds, with times in ms at this edge (pulse_width_min_ms, …)
CHECKS: dict[str, Spec] = {
    edge_name(f.name, "ms") if f.name.endswith("_s") else f.name:
        Number(ge=0, unit="ms") if f.name.endswith("_s") else _CHECK_BOUNDS.get(f.name, Number(ge=0))
    for f in fields(CheckConfig)
}
CHECK_KEYS = set(CHECKS)


def _acquisition(doc: dict[str, Any], where: Where) -> AcquisitionSpec:
    samples = value(doc, "samples", Integer(256, 2**24, default=AcquisitionSpec.samples), where)
    schema: dict[str, Spec] = {
        "sample_rate_hz": Number(ge=1000, le=1e6),
        "samples": Integer(256, 2**24),
        "pretrigger_samples": Integer(0, samples // 2),
        "trigger_level_n": Number(gt=0),
        "impacts_per_step": Integer(1, 100),
        "max_rehits": Integer(0, 100),
        "timeout_s": Number(gt=0),
        "retries": Integer(0, 20),
    }
    return build(AcquisitionSpec, doc, schema, where)


def _specimen(doc: dict[str, Any], where: Where, loading: LoadingSpec) -> SpecimenSpec:
    known = tuple(sorted(materials()))
    types = sorted(rollers())
    type_names = f"a catalogue roller type ({', '.join(map(str, types))})"
    t = read({k: v for k, v in doc.items() if k != "conditions"}, {
        "kind": Text(("roller", "ball"), default="roller"),
        "label": Text(default=None),
        "roller_type": Integer(default=None),
        "ball_diameter_mm": Number(gt=0, le=100, unit="mm", default=None),
        "ball_material": Text(known, default="1.3505"),
        "rail_material": Text(known, default="1.3505"),
        "rail_ra_um": Number(ge=0, le=MAX_RA_UM, unit="um", default=0.2),
        "max_load_n": Number(gt=0, default=None),
        "knob_step_deg": Number(gt=0, le=3600, default=loading.knob_step_deg),
    }, where)
    roller_type = t.get("roller_type")
    ball_d = t.get("ball_diameter_m")
    if t["kind"] == "roller":
        if roller_type is None:
            raise where.missing("roller_type", type_names)
        if roller_type not in types:
            raise where.bad("roller_type", roller_type, type_names)
        cap = c0_cap_n("roller", roller_type, t["rail_material"], loading)
        assert cap is not None
        max_load = t.get("max_load_n", cap)
        if max_load > cap * (1 + 1e-9):
            raise where.bad("max_load_n", max_load, f"at most the C0 cap {cap:.1f} N "
                            f"({loading.max_load_fraction_c0:g} × C0 of roller type {roller_type})")
        label = t.get("label", f"roller type {roller_type}")
    else:
        if ball_d is None:
            raise where.missing("ball_diameter_mm", "the ball's diameter in mm")
        if "max_load_n" not in t:
            raise where.missing("max_load_n", "the largest load in N (balls have no C0 cap here)")
        max_load = t["max_load_n"]
        label = t.get("label", f"ball {ball_d * 1e3:g} mm")
    return SpecimenSpec(kind=t["kind"], label=label, roller_type=roller_type, ball_diameter_m=ball_d,
                        ball_material=t["ball_material"], rail_material=t["rail_material"],
                        rail_ra_m=t["rail_ra_m"], max_load_n=max_load, knob_step_deg=t["knob_step_deg"],
                        conditions=_conditions(doc, where))


CONDITIONS: dict[str, Spec] = {
    "lubrication": Text(LUBRICATIONS, default=None),
    "lubricant": Text(default=None),
    "orientation_deg": Number(ge=0, le=90, default=None),
    "roller_ra_um": Number(ge=0, le=MAX_RA_UM, unit="um", default=None),
    "rail_ra_measured_um": Number(ge=0, le=MAX_RA_UM, unit="um", default=None),
    "roundness_um": Number(ge=0, le=1000, unit="um", default=None),
    "cylindricity_um": Number(ge=0, le=1000, unit="um", default=None),
}


def _conditions(doc: dict[str, Any], where: Where) -> SpecimenConditions:
    """The optional ``[specimen.conditions]`` table: lubrication, orientation, measured roughness and form."""
    table = value(doc, "conditions", Table(default={}), where)
    inner = where.at("conditions")
    check_keys(table, set(CONDITIONS), inner)
    t = read(table, CONDITIONS, inner)
    if "lubricant" in t and t.get("lubrication") in (None, "dry"):
        raise inner.bad("lubricant", t["lubricant"], 'a product name only with lubrication = "oil" or "grease"')
    return SpecimenConditions(**{k: t.get(k) for k in (f.name for f in fields(SpecimenConditions))})


def parse_protocol(text: str, path: str = "<protocol>") -> Protocol:
    """Validate protocol TOML text."""
    doc = parse_toml(text, path)
    top = Where(path)
    if "characterisation" in doc:
        raise top.problem("a spring characterisation protocol: run it with `labctl springs characterise`")
    check_keys(doc, TOP_KEYS, top)
    head = read(value(doc, "protocol", Table(default={}), top), HEAD, top.at("protocol"))
    loading = build(LoadingSpec, value(doc, "loading", Table(default={}), top), LOADING, top.at("loading"))
    if "specimen" in doc and "specimens" in doc:
        raise top.problem("give either [specimen] or [[specimens]], not both")
    if "specimen" in doc:
        raw = [(value(doc, "specimen", Table(), top), top.at("specimen"))]
    else:
        listed = value(doc, "specimens", Tables(default=[]), top)
        raw = [(s, top.at("specimens").at(i)) for i, s in enumerate(listed)]
    if not raw:
        raise top.problem("missing [specimen] table (or [[specimens]] array) naming what is tested")
    for entry, where in raw:
        check_keys(entry, SPECIMEN_KEYS, where)
    specimens = tuple(_specimen(entry, where, loading) for entry, where in raw)
    checks = build(CheckConfig, value(doc, "checks", Table(default={}), top), CHECKS, top.at("checks"))
    acquisition = _acquisition(value(doc, "acquisition", Table(default={}), top), top.at("acquisition"))
    repetitions = build(RepetitionSpec, value(doc, "repetitions", Table(default={}), top), REPETITIONS,
                        top.at("repetitions"))
    return Protocol(
        name=head.get("name", Path(path).stem),
        description=head["description"],
        specimens=specimens,
        loading=loading,
        acquisition=acquisition,
        repetitions=repetitions,
        checks=checks,
        source_path=path,
        source_text=text,
        static=parse_static(doc, top),
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
