"""The stiffness-table CSV: one measured roller stiffness per row, read and written.

Units live only in the column names (mm, µm, GPa at this edge; SI in :class:`StiffnessPoint`). Optional
columns default to a bearing-steel roller (1.3505: 210 GPa, ν 0.29, HRC 60) between bearing-steel rails; the
optional ``rail_material`` column names the rails' catalogue material.
"""

from __future__ import annotations

import csv
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Any

from labctl.data.csvfile import read_csv_records
from labctl.data.schema import MAX_RA_UM
from labctl.errors import InputError
from labctl.physics.catalogue import Roller, rollers
from labctl.physics.effects import ContactCase
from labctl.physics.materials import BEARING_STEEL, Material, material, materials

DEFAULT_ROLLER_RA_M = 0.03e-6
MAX_SIZE_MM = 1000.0
"""The largest diameter or length a table may give, mm: no roller of this rig is near it, and far past it the
contact formulas overflow."""
GEOMETRY_MATCH = 0.01

REQUIRED = ("diameter_mm", "contact_length_mm", "rail_ra_um", "load_n", "stiffness_n_per_m")
# The measured stiffness's 1-σ and its budget by source, as `labctl process` writes them (informative columns).
BUDGET_COLUMNS = {"modal_fit": "stiffness_std_fit_n_per_m", "disc_mass": "stiffness_std_mass_n_per_m",
                  "setup_stiffness": "stiffness_std_setup_n_per_m", "rig_model": "stiffness_std_model_n_per_m"}
OPTIONAL = ("roller_type", "roller_length_mm", "material", "youngs_modulus_gpa", "poisson_ratio", "hardness_hrc",
            "repetition", "rail_material", "stiffness_std_n_per_m", *BUDGET_COLUMNS.values(), "load_std_n",
            "load_after_n", "flags")
# What happened at a step that a user of its point must weigh (``flags``, separated by ";"):
FLAG_LOAD_DRIFT = "load_drift"  # the load did not hold during the step (the operator continued past the suspend)
FLAG_CHANNELS = "channels_left_out"  # a dead or saturated channel was left out of the step
FLAG_OVERRIDE = "operator_override"  # the operator overruled the checks on a blow of the step
COLUMNS = REQUIRED + OPTIONAL


class RollerContact:
    """The contact case of anything that names a roller and its rails (a table row, a stored specimen): needs
    ``diameter_m``, ``contact_length_m``, ``roller_length_m``, ``roller_type``, ``material``, ``youngs_modulus_pa``,
    ``poisson_ratio``, ``hardness_hrc``, ``rail_material`` and ``rail_ra_m``."""

    diameter_m: float
    contact_length_m: float
    rail_ra_m: float
    roller_type: int | None
    roller_length_m: float | None
    material: str | None
    youngs_modulus_pa: float | None
    poisson_ratio: float | None
    hardness_hrc: float | None
    rail_material: str | None

    def roller_material(self) -> Material:
        """The roller's material: catalogue values for a known name, overridden by any explicit column."""
        name = self.material or BEARING_STEEL
        known = materials()
        if name not in known and (self.youngs_modulus_pa is None or self.poisson_ratio is None):
            raise InputError(f"unknown material {name!r}: give youngs_modulus_gpa and poisson_ratio, or use one of "
                             f"{', '.join(sorted(known))}")
        base = known.get(name) or material(BEARING_STEEL)
        return Material(
            name=name,
            youngs_modulus_pa=base.youngs_modulus_pa if self.youngs_modulus_pa is None else self.youngs_modulus_pa,
            poisson_ratio=base.poisson_ratio if self.poisson_ratio is None else self.poisson_ratio,
            hardness_hrc=base.hardness_hrc if self.hardness_hrc is None else self.hardness_hrc,
        )

    def rail(self) -> Material:
        """The rails' catalogue material (bearing steel 1.3505 when the table does not say)."""
        name = self.rail_material or BEARING_STEEL
        known = materials()
        if name not in known:
            raise InputError(f"unknown rail material {name!r}: use one of {', '.join(sorted(known))}")
        return known[name]

    def case(self) -> ContactCase:
        """Roller between rails of the given material (default bearing steel) and Ra.

        The roller's own Ra comes from the catalogue when ``roller_type`` names a catalogue roller of the same
        geometry (within 1 %), else the catalogue default 0.03 µm.
        """
        roller = Roller(
            diameter_m=self.diameter_m,
            contact_length_m=self.contact_length_m,
            total_length_m=self.roller_length_m or self.contact_length_m,
            material=self.roller_material(),
            roughness_ra_m=_catalogue_roller_ra_m(self.roller_type, self.diameter_m, self.contact_length_m),
            type_id=self.roller_type,
        )
        return ContactCase(roller=roller, rail=self.rail(), rail_ra_m=self.rail_ra_m)


@dataclass(frozen=True)
class StiffnessPoint(RollerContact):
    """One measured roller stiffness at one load, with the contact it was measured on (SI units)."""

    diameter_m: float
    contact_length_m: float
    rail_ra_m: float
    load_n: float
    stiffness_n_per_m: float
    roller_type: int | None = None
    roller_length_m: float | None = None
    material: str | None = None
    youngs_modulus_pa: float | None = None
    poisson_ratio: float | None = None
    hardness_hrc: float | None = None
    repetition: int | None = None
    rail_material: str | None = None
    """Catalogue name of the rails' material (None: 1.3505 bearing steel)."""
    stiffness_std_n_per_m: float | None = None
    """1-σ of the measured stiffness (all sources), N/m."""
    stiffness_std_fit_n_per_m: float | None = None
    """Its modal-fit share (what repeated measurements on this rig scatter by), N/m."""
    stiffness_std_mass_n_per_m: float | None = None
    """Its disc-mass share (common to every point of one rig), N/m."""
    stiffness_std_setup_n_per_m: float | None = None
    """Its K_setup share (common to every point of one rig, larger for stiffer contacts), N/m."""
    stiffness_std_model_n_per_m: float | None = None
    """Its rig-model share (the 6-DOF idealisation), N/m."""
    load_std_n: float | None = None
    """1-σ of the load per roller when it came from the characterised spring curve (``load_source = "springs"``),
    N; None: read from a load cell (its noise is negligible against the stiffness scatter)."""
    load_after_n: float | None = None
    """The load per roller read after the step's blows, N (``load_n`` is the one read before them)."""
    flags: str | None = None
    """What happened at the step (FLAG_* names separated by ";"); a point flagged load_drift belongs to a load
    between load_n and load_after_n."""

    @property
    def drifted(self) -> bool:
        """The load did not hold during the step this point was measured at."""
        return FLAG_LOAD_DRIFT in (self.flags or "").split(";")


def _catalogue_roller_ra_m(type_id: int | None, diameter_m: float, contact_length_m: float) -> float:
    known = rollers().get(type_id) if type_id is not None else None
    if known is None:
        return DEFAULT_ROLLER_RA_M
    same = (abs(known.diameter_m / diameter_m - 1.0) <= GEOMETRY_MATCH
            and abs(known.contact_length_m / contact_length_m - 1.0) <= GEOMETRY_MATCH)
    return known.roughness_ra_m if same else DEFAULT_ROLLER_RA_M


def _positive(v: Decimal) -> bool:
    return v > 0


def _non_negative(v: Decimal) -> bool:
    return v >= 0


def _poisson(v: Decimal) -> bool:
    return Decimal(-1) < v < Decimal("0.5")


def _up_to(top: float, *, zero: bool = False) -> Callable[[Decimal], bool]:
    """A check for values in (0, top], or [0, top] with ``zero``."""
    return lambda v: (v >= 0 if zero else v > 0) and v <= Decimal(top)


def _integer(text: str) -> int:
    value = _number(text)
    if value != value.to_integral_value():
        raise ValueError(text)
    return int(value)


def _number(text: str) -> Decimal:
    try:
        value = Decimal(text)
    except InvalidOperation:
        raise ValueError(text) from None
    if not value.is_finite():
        raise ValueError(text)
    return value


# column -> (field, decimal exponent from the column's unit to SI, parser, check, what is expected)
_Spec = tuple[str, int, Callable[[str], Any], Callable[[Any], bool] | None, str]
_SPECS: dict[str, _Spec] = {
    "diameter_mm": ("diameter_m", -3, _number, _up_to(MAX_SIZE_MM), f"a diameter in (0, {MAX_SIZE_MM:g}] mm"),
    "contact_length_mm": ("contact_length_m", -3, _number, _up_to(MAX_SIZE_MM),
                          f"a contact length L_we in (0, {MAX_SIZE_MM:g}] mm"),
    "rail_ra_um": ("rail_ra_m", -6, _number, _up_to(MAX_RA_UM, zero=True),
                   f"a rail roughness Ra in [0, {MAX_RA_UM:g}] µm (ISO 1302's coarsest grade, N12)"),
    "load_n": ("load_n", 0, _number, _positive, "a positive load per roller in N"),
    "stiffness_n_per_m": ("stiffness_n_per_m", 0, _number, _positive, "a positive stiffness in N/m"),
    "roller_type": ("roller_type", 0, _integer, None, "an integer roller type"),
    "roller_length_mm": ("roller_length_m", -3, _number, _up_to(MAX_SIZE_MM),
                         f"a total roller length L_r in (0, {MAX_SIZE_MM:g}] mm"),
    "material": ("material", 0, str, None, "a material name"),
    "youngs_modulus_gpa": ("youngs_modulus_pa", 9, _number, _up_to(1500.0),
                           "a Young's modulus in (0, 1500] GPa (diamond's is about 1100)"),
    "poisson_ratio": ("poisson_ratio", 0, _number, _poisson, "a Poisson ratio in (-1, 0.5)"),
    "hardness_hrc": ("hardness_hrc", 0, _number, _up_to(100.0), "a Rockwell C hardness in (0, 100]"),
    "repetition": ("repetition", 0, _integer, None, "an integer repetition number"),
    "rail_material": ("rail_material", 0, str, None, "a rail material name"),
    **{c: (c, 0, _number, _non_negative, "a stiffness uncertainty ≥ 0 in N/m")
       for c in ("stiffness_std_n_per_m", *BUDGET_COLUMNS.values())},
    "load_std_n": ("load_std_n", 0, _number, _non_negative, "a load uncertainty ≥ 0 in N"),
    "load_after_n": ("load_after_n", 0, _number, _positive, "a positive load per roller in N"),
    "flags": ("flags", 0, str, None, "flags separated by ';'"),
}


def _cell(path: Path, row: int, column: str, text: str) -> Any:
    attr, exponent, parse, check, expected = _SPECS[column]
    where = f"{path}: row {row}, column {column}"
    try:
        value = parse(text)
    except ValueError:
        raise InputError(f"{where}: {text!r} is not {expected}") from None
    if check is not None and not check(value):
        raise InputError(f"{where}: {text!r} is not {expected}")
    return float(value.scaleb(exponent)) if isinstance(value, Decimal) else value


def _row_point(path: Path, row: int, record: dict[str, str]) -> StiffnessPoint:
    values: dict[str, Any] = {}
    for column in COLUMNS:
        text = (record.get(column) or "").strip()
        if not text:
            if column in REQUIRED:
                raise InputError(f"{path}: row {row}, column {column}: empty, expected {_SPECS[column][4]}")
            continue
        values[_SPECS[column][0]] = _cell(path, row, column, text)
    point = StiffnessPoint(**values)
    try:
        point.roller_material()
    except InputError as exc:
        raise InputError(f"{path}: row {row}, column material: {exc}") from None
    try:
        point.rail()
    except InputError as exc:
        raise InputError(f"{path}: row {row}, column rail_material: {exc}") from None
    return point


def read_stiffness_table(path: str | Path) -> list[StiffnessPoint]:
    """Parse a stiffness-table CSV; any problem is an InputError naming the file, row, column and value."""
    p = Path(path)
    records = read_csv_records(p, what="stiffness-table CSV", required=REQUIRED)
    points = [_row_point(p, line, record) for line, record in records]
    if not points:
        raise InputError(f"{p}: no data rows (expected one row per measured point under the header)")
    return points


def _format(value: Any, exponent: int) -> str:
    if value is None:
        return ""
    if isinstance(value, str | int):
        return str(value)
    return f"{float(value) * 10.0 ** -exponent:.12g}"


def write_stiffness_table(path: str | Path, points: Iterable[StiffnessPoint]) -> None:
    """Write points as a stiffness-table CSV: required columns always, optional ones when any point has them."""
    rows = list(points)
    columns = [c for c in COLUMNS if c in REQUIRED or any(getattr(r, _SPECS[c][0]) is not None for r in rows)]
    with Path(path).open("w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(columns)
        for r in rows:
            writer.writerow([_format(getattr(r, _SPECS[c][0]), _SPECS[c][1]) for c in columns])
