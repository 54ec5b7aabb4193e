"""World scenarios: the physics hidden in the simulated rig's data, read from a TOML file (units at the edge).

A world is a contact law (a library baseline or a world law of ``labctl.physics.world_laws`` — physical, tabulated
or a safe expression — followed by effect terms of ``labctl.physics.effects``), the rig's true setup stiffness
relative to its nominal value, per-seating scatter of law parameters, optional overrides of the simulated
instruments and the rates and sizes of instrument faults. The simulator evaluates it; the discrepancy workflow
must find what it hides. Every table is read with ``labctl.data.schema`` (one error format, NaN/inf refused) and
every edge unit converted by ``labctl.data.units``, like the other configuration files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from dataclasses import fields as dataclass_fields
from pathlib import Path
from typing import Any

import numpy as np

from drivers.sim import FaultSettings, SimSettings
from labctl.data import data_path, read_toml
from labctl.data.schema import (
    Integer,
    Number,
    Numbers,
    Spec,
    Table,
    Tables,
    Text,
    Where,
    bounded,
    check_keys,
    read,
    value,
    value_name,
)
from labctl.data.units import AUTO_UNITS, MM, edge_name, to_si
from labctl.errors import InputError
from labctl.physics.catalogue import Roller
from labctl.physics.effects import EFFECTS, ContactCase, Effect, SetupCompliance
from labctl.physics.law import BASELINES, ContactLaw
from labctl.physics.materials import Material
from labctl.physics.rig_config import RigConfig
from labctl.physics.tripp import DEFAULT_DEPTH_M
from labctl.physics.world_laws import WORLD_BASELINES, ConformingContact, ExpressionLaw, TabulatedLaw, WorldLaw

DEFAULT_WORLD = "default"
WORLDS_DIR = "worlds"
SI_SUFFIXES = ("_m", "_rad", "_s", "_pa")
BASE = -1  # index of a world law's own baseline in Scatter.parameters (effects count from 0)


def _stem(si_name: str) -> str:
    """Parameter name without its SI unit: the prefix of its ``<stem>_rel`` scatter key."""
    return next((si_name[: -len(s)] for s in SI_SUFFIXES if si_name.endswith(s)), si_name)


@dataclass(frozen=True)
class Scatter:
    """Redrawn each time a roller is seated: lognormal σ per effect parameter, and a load-independent σ."""

    stiffness_rel: float = 0.0
    parameters: tuple[tuple[int, str, float], ...] = ()  # (effect index in the law or BASE, SI parameter, σ)


@dataclass(frozen=True)
class SeatedRoller:
    """One roller on its current contact spot: the world's law with this seating's parameters."""

    law: ContactLaw | WorldLaw
    case: ContactCase
    factor: float = 1.0

    def stiffness_n_per_m(self, load_n: float) -> float:
        return float(self.stiffness_curve_n_per_m(load_n))

    def stiffness_curve_n_per_m(self, loads_n: np.ndarray | float) -> np.ndarray:
        return self.factor * np.asarray(self.law.stiffness_n_per_m(self.case, loads_n), dtype=float)


@dataclass(frozen=True)
class BurrSeated:
    """A roller seated on a burr or particle: a thin extra layer in series, stiffness F/gap (softest at low load)."""

    inner: SeatedRoller
    gap_m: float

    def stiffness_n_per_m(self, load_n: float) -> float:
        return float(self.stiffness_curve_n_per_m(load_n))

    def stiffness_curve_n_per_m(self, loads_n: np.ndarray | float) -> np.ndarray:
        return 1.0 / (1.0 / self.inner.stiffness_curve_n_per_m(loads_n) + self.gap_m / np.asarray(loads_n))


@dataclass(frozen=True)
class WorldSpecimen:
    """The rollers of one contact case in a world; ``seat`` draws a new contact spot."""

    world: World
    case: ContactCase

    def seat(self, rng: np.random.Generator) -> SeatedRoller:
        law = self.world.law
        effects = list(law.effects)
        for index, param, sigma in self.world.scatter.parameters:
            term = law.base if index == BASE else effects[index]  # type: ignore[union-attr]
            lo, hi = term.BOUNDS[param]
            value = float(np.clip(getattr(term, param) * math.exp(sigma * rng.standard_normal()), lo, hi))
            if index == BASE:
                law = law.with_base(**{param: value})  # type: ignore[union-attr]
            else:
                effects[index] = replace(term, **{param: value})  # type: ignore[type-var]
        reseated = getattr(getattr(law, "base", None), "reseated", None)
        if reseated is not None:
            law = replace(law, base=reseated(rng))
        sigma = self.world.scatter.stiffness_rel
        factor = math.exp(sigma * rng.standard_normal()) if sigma > 0 else 1.0
        return SeatedRoller(replace(law, effects=tuple(effects)), self.case, factor)

    def on_burr(self, seated: SeatedRoller, gap_m: float) -> BurrSeated:
        """``seated`` with a burr or particle of height ``gap_m`` under it."""
        return BurrSeated(seated, gap_m)


@dataclass(frozen=True)
class World:
    """Hidden physics of a simulated rig."""

    law: ContactLaw | WorldLaw
    setup_stiffness_factor: float = 1.0
    scatter: Scatter = field(default_factory=Scatter)
    instruments: dict[str, float] = field(default_factory=dict)  # SI overrides of the simulator's settings
    faults: dict[str, float] = field(default_factory=dict)  # SI rates and sizes of the simulator's faults
    source: str = ""
    description: str = ""
    rig_overrides: tuple[tuple[str, str, float], ...] = ()  # (rig-file table, key, value in the file's units)

    def true_rig(self, rig: RigConfig) -> RigConfig:
        """The rig as it really is in this world: the ``[rig]`` table's values, then K_setup times the factor."""
        rig = override_rig(rig, self.rig_overrides)
        if self.setup_stiffness_factor == 1.0:
            return rig
        return rig.with_setup_stiffness(self.setup_stiffness_factor * rig.setup_stiffness_n_per_m)

    def specimen(self, case: ContactCase) -> WorldSpecimen:
        return WorldSpecimen(self, case)

    @property
    def effect_names(self) -> tuple[str, ...]:
        """Effects hidden in the data, including a setup stiffness off its nominal value."""
        setup = (SetupCompliance.name,) if self.setup_stiffness_factor != 1.0 else ()
        return self.law.effect_names + setup


def ball(diameter_m: float, material: Material, roughness_ra_m: float = 0.01e-6) -> Roller:
    """A bearing ball as the rolling element of a contact case (world baseline ``hertz``: only D matters)."""
    return Roller(diameter_m, diameter_m, diameter_m, material, roughness_ra_m)


def shipped_worlds() -> list[str]:
    """Names of the world files shipped with labctl (``labctl/data/worlds/<name>.toml``)."""
    return sorted(p.stem for p in data_path(WORLDS_DIR).glob("*.toml"))


def world_path(world: str | Path | None) -> Path:
    """A world file: an existing path, or the name of a shipped world (``None``: the default world)."""
    if world is None:
        world = DEFAULT_WORLD
    p = Path(world)
    if p.exists() or p.suffix or len(p.parts) > 1:
        return p
    shipped = data_path(f"{WORLDS_DIR}/{p.name}.toml")
    if shipped.exists():
        return shipped
    raise InputError(f"world {str(world)!r}: no such file or shipped world; shipped: {', '.join(shipped_worlds())}")


TOP: dict[str, Spec] = {
    "description": Text(default=""), "baseline": Table(), "effects": Table(default={}), "scatter": Table(default={}),
    "instruments": Table(default={}), "faults": Table(default={}), "rig": Table(default={}),
}


def load_world(path: str | Path | None = None) -> World:
    """Read a world scenario file (the shipped default without a path), naming the file, table and key of any
    error in the one format of ``labctl.data.schema``."""
    p = world_path(path)
    top = Where(str(p))
    doc = read(read_toml(p), TOP, top)
    law, setup_factor, params = _law(doc["baseline"], doc["effects"], top)
    scatter = read(doc["scatter"], {"stiffness_rel": Number(ge=0, le=1, default=0.0)}, top.at("scatter"))
    return World(
        law=law,
        setup_stiffness_factor=setup_factor,
        scatter=Scatter(scatter["stiffness_rel"], params),
        instruments=_settings(doc["instruments"], SimSettings, top.at("instruments")),
        faults=_settings(doc["faults"], FaultSettings, top.at("faults")),
        source=str(p),
        description=doc["description"],
        rig_overrides=rig_overrides(doc["rig"], top.at("rig")),
    )


# The world's [rig] table: the true rig where it differs from the rig file, with the rig file's tables and keys.
RIG_KEYS: dict[str, tuple[str, ...]] = {
    "upper_disc": ("mass_kg", "inertia_kg_m2", "thickness_mm"),
    "lower_disc": ("mass_kg", "inertia_kg_m2", "thickness_mm"),
    "contacts": ("radius_mm", "setup_stiffness_n_per_m"),
    "support": ("stiffness_n_per_m", "radius_mm", "damping_ratio"),
    "damping": ("modal_damping_ratio",),
}


def rig_overrides(doc: dict[str, Any], where: Where) -> tuple[tuple[str, str, float], ...]:
    """Validate a world's ``[rig]`` table: known rig-file tables and keys, positive finite numbers (kept in the
    rig file's units, in file order)."""
    tables = read(doc, dict.fromkeys(RIG_KEYS, Table(default=None)), where)
    out: list[tuple[str, str, float]] = []
    for name in doc:
        values = read(tables[name], dict.fromkeys(RIG_KEYS[name], Number(gt=0, default=None)), where.at(name))
        out.extend((name, key, values[key]) for key in tables[name])
    return tuple(out)


def override_rig(rig: RigConfig, overrides: tuple[tuple[str, str, float], ...]) -> RigConfig:
    """The rig with a world's ``[rig]`` values (rig-file units, converted to SI) in place of the file's."""
    discs = {"upper_disc": rig.upper, "lower_disc": rig.lower}
    fields: dict[str, Any] = {}
    for table, key, edge_value in overrides:
        name, si = to_si(key, edge_value)
        if table in discs:
            discs[table] = replace(discs[table], **{name: si})
        else:
            name = {("contacts", "radius_m"): "contact_radius_m", ("support", "stiffness_n_per_m"):
                    "support_stiffness_n_per_m", ("support", "radius_m"): "support_radius_m",
                    ("support", "damping_ratio"): "support_damping_ratio"}.get((table, name), name)
            fields[name] = si
    if not overrides:
        return rig
    return replace(rig, upper=discs["upper_disc"], lower=discs["lower_disc"], **fields)


def _law(
    baseline: dict[str, Any], effects_doc: dict[str, Any], top: Where
) -> tuple[ContactLaw | WorldLaw, float, tuple[tuple[int, str, float], ...]]:
    b_where = top.at("baseline")
    model = value(baseline, "model", Text((*BASELINES, *WORLD_BASELINES)), b_where)
    base: ConformingContact | TabulatedLaw | ExpressionLaw | None = None
    scatter: list[tuple[int, str, float]] = []
    depth_m = DEFAULT_DEPTH_M
    if model in WORLD_BASELINES:
        base, base_rel = _world_baseline(model, baseline, b_where)
        scatter.extend((BASE, param, sigma) for param, sigma in base_rel.items())
    else:
        schema: dict[str, Spec] = {"model": Text()}
        if model == "tripp":
            schema["depth_mm"] = Number(ge=1e-3, le=1e3, unit="mm", default=DEFAULT_DEPTH_M / MM)
        depth_m = read(baseline, schema, b_where).get("depth_m", DEFAULT_DEPTH_M)
    e_where = top.at("effects")
    check_keys(effects_doc, EFFECTS, e_where)
    effects: list[Effect] = []
    setup_factor = 1.0
    for name in effects_doc:  # in file order: effects apply in the order written
        table = value(effects_doc, name, Table(), e_where)
        values, rel = _effect_parameters(EFFECTS[name], table, e_where.at(name))
        if name == SetupCompliance.name:
            if rel:
                raise e_where.at(name).problem("the setup stiffness has no per-seating scatter")
            setup_factor = values.get("stiffness_factor", SetupCompliance().stiffness_factor)
            continue
        scatter.extend((len(effects), param, sigma) for param, sigma in rel.items())
        effects.append(EFFECTS[name](**values))
    if base is not None:
        return WorldLaw(base, tuple(effects)), setup_factor, tuple(scatter)
    return ContactLaw(model, depth_m, tuple(effects)), setup_factor, tuple(scatter)


TABLE_ENTRY: dict[str, Spec] = {
    "roller_type": Integer(), "load_n": Numbers(Number(gt=0)), "stiffness_n_per_m": Numbers(Number(gt=0)),
}


def _world_baseline(
    model: str, table: dict[str, Any], where: Where
) -> tuple[ConformingContact | TabulatedLaw | ExpressionLaw, dict[str, float]]:
    """A world's own contact law (``labctl.physics.world_laws``) from its ``[baseline]`` table."""
    if model == "expression":
        text = read(table, {"model": Text(), "expression": Text()}, where)["expression"]
        try:
            return ExpressionLaw(text), {}
        except ValueError as exc:
            raise where.bad("expression", text, f"a safe arithmetic expression ({exc})") from None
    if model == "table":
        entries = read(table, {"model": Text(), "tables": Tables()}, where)["tables"]
        return TabulatedLaw(_tables(entries, where)), {}
    values, rel = _effect_parameters(ConformingContact, table, where, extra={"model": Text()})
    return ConformingContact(**values), rel


Curve = tuple[int, tuple[float, ...], tuple[float, ...]]  # (roller type, loads N, stiffnesses N/m)


def _tables(entries: list[dict[str, Any]], where: Where) -> tuple[Curve, ...]:
    out: list[Curve] = []
    for i, entry in enumerate(entries):
        e_where = where.at("tables").at(i)
        t = read(entry, TABLE_ENTRY, e_where)
        loads, ks = t["load_n"], t["stiffness_n_per_m"]
        if len(loads) < 2 or len(loads) != len(ks) or any(b <= a for a, b in zip(loads, loads[1:], strict=False)):
            raise e_where.problem("load_n must rise strictly and match stiffness_n_per_m in length (>= 2)")
        if t["roller_type"] in (o[0] for o in out):
            raise e_where.bad("roller_type", t["roller_type"], "a roller type without a table yet (one per type)")
        out.append((t["roller_type"], loads, ks))
    if not out:
        raise where.bad("tables", entries, "at least one [[baseline.tables]] entry")
    return tuple(out)


def _effect_parameters(
    cls: type, table: dict[str, Any], where: Where, extra: dict[str, Spec] | None = None
) -> tuple[dict[str, float], dict[str, float]]:
    """An effect's (or world law's) SI parameter values, read in their edge units against its ``BOUNDS``, and the
    lognormal σ of those that scatter per seating (``<stem>_rel``); ``extra`` keys are checked and dropped."""
    bounds: dict[str, tuple[float, float]] = cls.BOUNDS  # type: ignore[attr-defined]
    stems = {f"{_stem(p)}_rel": p for p in bounds}
    schema = {**(extra or {}), **bounded(bounds), **dict.fromkeys(stems, Number(ge=0, le=1, default=None))}
    got = read(table, schema, where)
    for key in extra or {}:
        got.pop(key)
    rel = {stems[k]: got.pop(k) for k in stems if k in got}
    return got, rel


def _settings(table: dict[str, Any], cls: type, where: Where) -> dict[str, float]:
    """Simulator settings (``SimSettings`` or ``FaultSettings`` fields) the world overrides, read in SI or in an
    edge unit (``pulse_width_min_ms``, ``unequal_seating_gap_um``; not a rate ``_per_``) and returned under their
    SI names, checked against the settings' own ranges (``drivers.sim``, their one source of truth)."""
    schema: dict[str, Spec] = {}
    for f in dataclass_fields(cls):
        schema[f.name] = Integer() if f.type in (int, "int") else Number()
        if "_per_" not in f.name and isinstance(schema[f.name], Number):
            for unit in AUTO_UNITS:
                edge = edge_name(f.name, unit)
                if edge != f.name:
                    schema[edge] = Number(unit=unit)
    values = read(table, {k: replace(s, default=None) for k, s in schema.items()}, where)
    by_si: dict[str, str] = {}
    for key in table:
        si = value_name(key, schema[key])
        if si in by_si:
            raise where.problem(f"{by_si[si]} and {key} both set {si}; give one")
        by_si[si] = key
    try:
        cls(**values)  # the settings' own ranges (a rate is a probability, a pulse-width range rises)
    except ValueError as exc:
        raise where.problem(str(exc)) from None
    return {si: values[si] for si in by_si}  # in file order
