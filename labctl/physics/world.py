"""World scenarios: the physics hidden in the simulated rig's data, read from a TOML file (units at the edge).

A world is a contact law (a library baseline or a world law of ``labctl.physics.world_laws`` — physical, tabulated
or a safe expression — followed by effect terms of ``labctl.physics.effects``), the rig's true setup stiffness
relative to its nominal value, per-seating scatter of law parameters, optional overrides of the simulated
instruments and the rates and sizes of instrument faults. The simulator evaluates it; the discrepancy workflow
must find what it hides.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from labctl.data import data_path, read_toml, require
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
# edge unit suffix -> (SI suffix, factor to SI)
UNITS: dict[str, tuple[str, float]] = {
    "_mm": ("_m", 1e-3), "_um": ("_m", 1e-6), "_mrad": ("_rad", 1e-3), "_ms": ("_s", 1e-3), "_gpa": ("_pa", 1e9),
}
SI_SUFFIXES = ("_m", "_rad", "_s", "_pa")
TOP_LEVEL = {"description", "baseline", "effects", "scatter", "instruments", "faults", "rig"}
BASE = -1  # index of a world law's own baseline in Scatter.parameters (effects count from 0)


def to_si(key: str, value: float) -> tuple[str, float]:
    """``("edge_length_mm", 0.1)`` → ``("edge_length_m", 1e-4)``; keys without an edge unit pass unchanged."""
    for suffix, (si, factor) in UNITS.items():
        if key.endswith(suffix):
            return key[: -len(suffix)] + si, value * factor
    return key, value


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
        return self.factor * float(self.law.stiffness_n_per_m(self.case, load_n))


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


def load_world(path: str | Path | None = None) -> World:
    """Read a world scenario file (the shipped default without a path), naming the file and key of any error."""
    p = world_path(path)
    doc = read_toml(p)
    where = str(p)
    unknown = sorted(set(doc) - TOP_LEVEL)
    if unknown:
        raise InputError(f"{where}: unknown key(s) {', '.join(unknown)}; expected {', '.join(sorted(TOP_LEVEL))}")
    baseline = require(doc, "baseline", dict, where)
    law, setup_factor, params = _law(baseline, doc.get("effects", {}), where)
    scatter_doc = doc.get("scatter", {})
    _only(scatter_doc, {"stiffness_rel"}, f"{where}: scatter")
    stiffness_rel = _number(scatter_doc, "stiffness_rel", f"{where}: scatter", 0.0, 0.0, 1.0)
    return World(
        law=law,
        setup_stiffness_factor=setup_factor,
        scatter=Scatter(stiffness_rel, params),
        instruments=_instruments(doc.get("instruments", {}), f"{where}: instruments"),
        faults=_instruments(doc.get("faults", {}), f"{where}: faults"),
        source=where,
        description=str(doc.get("description", "")),
        rig_overrides=rig_overrides(doc.get("rig", {}), f"{where}: rig"),
    )


# The world's [rig] table: the true rig where it differs from the rig file, with the rig file's tables and keys.
RIG_KEYS: dict[str, tuple[str, ...]] = {
    "upper_disc": ("mass_kg", "inertia_kg_m2", "thickness_mm"),
    "lower_disc": ("mass_kg", "inertia_kg_m2", "thickness_mm"),
    "contacts": ("radius_mm", "setup_stiffness_n_per_m"),
    "support": ("stiffness_n_per_m", "radius_mm", "damping_ratio"),
    "damping": ("modal_damping_ratio",),
}


def rig_overrides(doc: Any, where: str) -> tuple[tuple[str, str, float], ...]:
    """Validate a world's ``[rig]`` table: known rig-file tables and keys, positive finite numbers."""
    if not isinstance(doc, dict):
        raise InputError(f"{where} = {doc!r}: expected a table of rig-file tables")
    out: list[tuple[str, str, float]] = []
    for table, values in doc.items():
        if table not in RIG_KEYS:
            raise InputError(f"{where}.{table}: unknown rig table; expected one of {', '.join(RIG_KEYS)}")
        if not isinstance(values, dict):
            raise InputError(f"{where}.{table} = {values!r}: expected a table of rig-file keys")
        for key in values:
            if key not in RIG_KEYS[table]:
                raise InputError(f"{where}.{table}.{key}: unknown key; expected one of {', '.join(RIG_KEYS[table])}")
            value = require(values, key, float, f"{where}.{table}")
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"{where}.{table}.{key} = {value!r}: expected a positive finite number")
            out.append((table, key, float(value)))
    return tuple(out)


def override_rig(rig: RigConfig, overrides: tuple[tuple[str, str, float], ...]) -> RigConfig:
    """The rig with a world's ``[rig]`` values (rig-file units: mm converted to m) in place of the file's."""
    discs = {"upper_disc": rig.upper, "lower_disc": rig.lower}
    fields: dict[str, Any] = {}
    for table, key, value in overrides:
        si = value * 1e-3 if key.endswith("_mm") else value
        if table in discs:
            name = "thickness_m" if key == "thickness_mm" else key
            discs[table] = replace(discs[table], **{name: si})
        else:
            name = {("contacts", "radius_mm"): "contact_radius_m", ("support", "stiffness_n_per_m"):
                    "support_stiffness_n_per_m", ("support", "radius_mm"): "support_radius_m",
                    ("support", "damping_ratio"): "support_damping_ratio"}.get((table, key), key)
            fields[name] = si
    if not overrides:
        return rig
    return replace(rig, upper=discs["upper_disc"], lower=discs["lower_disc"], **fields)


def _law(
    baseline: dict[str, Any], effects_doc: Any, where: str
) -> tuple[ContactLaw | WorldLaw, float, tuple[tuple[int, str, float], ...]]:
    b_where = f"{where}: baseline"
    model = require(baseline, "model", str, b_where)
    if model not in BASELINES and model not in WORLD_BASELINES:
        raise InputError(f"{b_where}.model = {model!r}: expected one of {', '.join((*BASELINES, *WORLD_BASELINES))}")
    base: ConformingContact | TabulatedLaw | ExpressionLaw | None = None
    scatter: list[tuple[int, str, float]] = []
    if model in WORLD_BASELINES:
        base, base_rel = _world_baseline(model, baseline, b_where)
        scatter.extend((BASE, param, sigma) for param, sigma in base_rel.items())
    else:
        _only(baseline, {"model", "depth_mm"} if model == "tripp" else {"model"}, b_where)
    depth_m = _number(baseline, "depth_mm", b_where, DEFAULT_DEPTH_M / 1e-3, 1e-3, 1e3) * 1e-3
    if not isinstance(effects_doc, dict):
        raise InputError(f"{where}: effects = {effects_doc!r}: expected a table of effect tables")
    effects: list[Effect] = []
    setup_factor = 1.0
    for name, table in effects_doc.items():
        e_where = f"{where}: effects.{name}"
        if name not in EFFECTS:
            raise InputError(f"{e_where}: unknown effect; expected one of {', '.join(EFFECTS)}")
        if not isinstance(table, dict):
            raise InputError(f"{e_where} = {table!r}: expected a table of parameters")
        values, rel = _effect_parameters(EFFECTS[name], table, e_where)
        if name == SetupCompliance.name:
            if rel:
                raise InputError(f"{e_where}: the setup stiffness has no per-seating scatter")
            setup_factor = values.get("stiffness_factor", SetupCompliance().stiffness_factor)
            continue
        scatter.extend((len(effects), param, sigma) for param, sigma in rel.items())
        effects.append(EFFECTS[name](**values))
    if base is not None:
        return WorldLaw(base, tuple(effects)), setup_factor, tuple(scatter)
    return ContactLaw(model, depth_m, tuple(effects)), setup_factor, tuple(scatter)


def _world_baseline(
    model: str, table: dict[str, Any], where: str
) -> tuple[ConformingContact | TabulatedLaw | ExpressionLaw, dict[str, float]]:
    """A world's own contact law (``labctl.physics.world_laws``) from its ``[baseline]`` table."""
    if model == "expression":
        _only(table, {"model", "expression"}, where)
        text = require(table, "expression", str, where)
        try:
            return ExpressionLaw(text), {}
        except ValueError as exc:
            raise InputError(f"{where}.expression = {text!r}: {exc}") from None
    if model == "table":
        _only(table, {"model", "tables"}, where)
        return TabulatedLaw(_tables(require(table, "tables", list, where), f"{where}.tables")), {}
    params = {k: v for k, v in table.items() if k != "model"}
    values, rel = _effect_parameters(ConformingContact, params, where)
    return ConformingContact(**values), rel


def _tables(entries: list[Any], where: str) -> tuple[tuple[int, tuple[float, ...], tuple[float, ...]], ...]:
    out = []
    for i, entry in enumerate(entries):
        e_where = f"{where}[{i}]"
        _only(entry, {"roller_type", "load_n", "stiffness_n_per_m"}, e_where)
        type_id = require(entry, "roller_type", int, e_where)
        loads = require(entry, "load_n", list, e_where)
        ks = require(entry, "stiffness_n_per_m", list, e_where)
        for key, values in (("load_n", loads), ("stiffness_n_per_m", ks)):
            if not all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and v > 0
                       for v in values):
                raise InputError(f"{e_where}.{key} = {values!r}: expected a list of positive numbers")
        if len(loads) < 2 or len(loads) != len(ks) or any(b <= a for a, b in zip(loads, loads[1:], strict=False)):
            raise InputError(f"{e_where}: load_n must rise strictly and match stiffness_n_per_m in length (>= 2)")
        if type_id in (t[0] for t in out):
            raise InputError(f"{e_where}.roller_type = {type_id}: a second table for the same roller type")
        out.append((type_id, tuple(float(v) for v in loads), tuple(float(v) for v in ks)))
    if not out:
        raise InputError(f"{where}: expected at least one [[baseline.tables]] entry")
    return tuple(out)


def _effect_parameters(cls: type, table: dict[str, Any], where: str) -> tuple[dict[str, float], dict[str, float]]:
    """An effect's SI parameter values (checked against its BOUNDS) and the σ of those that scatter."""
    bounds: dict[str, tuple[float, float]] = cls.BOUNDS  # type: ignore[attr-defined]
    stems = {f"{_stem(p)}_rel": p for p in bounds}
    values: dict[str, float] = {}
    rel: dict[str, float] = {}
    for key in table:
        if key in stems:
            rel[stems[key]] = _number(table, key, where, 0.0, 0.0, 1.0)
            continue
        si_key, _ = to_si(key, 0.0)
        if si_key not in bounds:
            expected = [*(_edge_name(p) for p in bounds), *stems]
            raise InputError(f"{where}.{key}: unknown parameter; expected {', '.join(expected)}")
        lo, hi = bounds[si_key]
        _, scale = to_si(key, 1.0)
        values[si_key] = _number(table, key, where, 0.0, lo / scale, hi / scale) * scale
    return values, rel


def _edge_name(si_name: str) -> str:
    for suffix, (si, factor) in UNITS.items():
        if si_name.endswith(si) and factor == 1e-3 and suffix in ("_mm", "_mrad"):
            return si_name[: -len(si)] + suffix
    return si_name


def _instruments(table: Any, where: str) -> dict[str, float]:
    if not isinstance(table, dict):
        raise InputError(f"{where} = {table!r}: expected a table of simulator settings")
    out: dict[str, float] = {}
    for key in table:
        value = require(table, key, float, where)
        if not math.isfinite(value):
            raise InputError(f"{where}.{key} = {value!r}: expected a finite number")
        si_key, si_value = to_si(key, value)
        out[si_key] = si_value
    return out


def _number(table: dict[str, Any], key: str, where: str, default: float, lo: float, hi: float) -> float:
    if key not in table:
        return default
    value = require(table, key, float, where)
    if not (math.isfinite(value) and lo <= value <= hi):
        raise InputError(f"{where}.{key} = {value!r}: expected a number in [{lo:g}, {hi:g}]")
    return float(value)


def _only(table: Any, allowed: set[str], where: str) -> None:
    if not isinstance(table, dict):
        raise InputError(f"{where} = {table!r}: expected a table")
    extra = sorted(set(table) - allowed)
    if extra:
        raise InputError(f"{where}: unknown key(s) {', '.join(extra)}; expected {', '.join(sorted(allowed))}")
