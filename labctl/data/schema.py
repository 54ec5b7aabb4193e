"""One way to read configuration files (protocol, rig, devices, catalogues, worlds): typed keys, one error format.

A table of a TOML file is read against a schema, a mapping from the key as written in the file to a typed spec
(``Number``, ``Integer``, ``Text``, ``Flag``, ``Numbers``, ``Table``, ``Tables``). Reading refuses unknown keys
(naming the closest valid one), missing required keys, wrong types, NaN/inf and values out of range, and converts
numbers from their edge unit to SI (``Number(unit="mm")`` on ``thickness_mm`` gives ``thickness_m`` in metres).

Every error is an ``InputError`` (one line, exit 2) of one of these forms, ``TABLE`` being the dotted TOML path
(``acquisition``, ``daq.channels[2]``, ``specimens[0]``; nothing at the top level)::

    FILE: TABLE.KEY = VALUE: expected WHAT
    FILE: TABLE: missing key 'KEY'; expected WHAT
    FILE: TABLE: unknown key(s) KEY (did you mean 'CLOSEST'?); expected one of KEY, KEY, ...
    FILE: TABLE: PROBLEM            (a rule across keys, e.g. a load above the roller's C0 cap)
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import MISSING, dataclass, fields, replace
from typing import Any, TypeVar

from labctl.data.units import edge_name, factor, si_name
from labctl.errors import InputError

T = TypeVar("T")


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


REQUIRED: Any = _Required()  # a spec's default meaning "the key must be given"
MAX_RA_UM = 50.0
"""The largest roughness Ra any file may give, µm: ISO 1302's coarsest grade (N12); no rolling surface is near it."""


@dataclass(frozen=True)
class Where:
    """A place in a configuration file (file and dotted table path) that builds the one error format."""

    file: str
    table: str = ""

    def at(self, key: str | int) -> Where:
        """The place of a sub-table (``"loading"``) or of an array entry (``2`` → ``channels[2]``)."""
        if isinstance(key, int):
            return Where(self.file, f"{self.table}[{key}]")
        return Where(self.file, f"{self.table}.{key}" if self.table else key)

    def path(self, key: str) -> str:
        return f"{self.table}.{key}" if self.table else key

    def _head(self) -> str:
        return f"{self.file}: {self.table}: " if self.table else f"{self.file}: "

    def bad(self, key: str, value: Any, expected: str) -> InputError:
        """``FILE: TABLE.KEY = VALUE: expected WHAT``."""
        return InputError(f"{self.file}: {self.path(key)} = {value!r}: expected {expected}")

    def missing(self, key: str, expected: str = "") -> InputError:
        """``FILE: TABLE: missing key 'KEY'; expected WHAT``."""
        return InputError(f"{self._head()}missing key '{key}'" + (f"; expected {expected}" if expected else ""))

    def unknown(self, keys: Iterable[str], valid: Iterable[str]) -> InputError:
        """Unknown keys, each with the closest valid key when one is close (difflib), and the valid ones."""
        import difflib  # only when there is an error to explain

        valid = sorted(valid)
        named = []
        for key in keys:
            close = difflib.get_close_matches(key, valid, n=1)
            named.append(f"{key} (did you mean '{close[0]}'?)" if close else key)
        return InputError(f"{self._head()}unknown key(s) {', '.join(named)}; expected one of {', '.join(valid)}")

    def problem(self, text: str) -> InputError:
        """``FILE: TABLE: PROBLEM`` for a rule across keys."""
        return InputError(f"{self._head()}{text}")


# ---- value specs ---------------------------------------------------------------------------------------------
def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


@dataclass(frozen=True)
class Number:
    """A finite real number (TOML integer or float; never a boolean, NaN or inf), bounded in its edge unit.

    ``unit`` is the unit written in the file (``mm``, ``um``, ``gpa``, ``mrad``, ``ms``, ``ma``, ``deg``): the value
    read is converted to SI and its key renamed (``thickness_mm`` → ``thickness_m``). Bounds are in the file's unit.
    """

    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    unit: str = ""
    default: Any = REQUIRED

    def describe(self, finite: bool = False) -> str:
        lo = (f"> {self.gt:g}", f"({self.gt:g}") if self.gt is not None else \
            (f"≥ {self.ge:g}", f"[{self.ge:g}") if self.ge is not None else None
        hi = (f"< {self.lt:g}", f"{self.lt:g})") if self.lt is not None else \
            (f"≤ {self.le:g}", f"{self.le:g}]") if self.le is not None else None
        noun = "a finite number" if finite else "a number"
        if lo and hi:
            return f"{noun} in {lo[1]}, {hi[1]}"
        if self.gt == 0 and not hi:
            return "a finite positive number" if finite else "a positive number"
        bound = (lo or hi or ("", ""))[0]
        return f"{noun} {bound}".strip()

    def read(self, key: str, value: Any, where: Where) -> float:
        if not _is_number(value):
            raise where.bad(key, value, f"float ({self.describe()})")
        x = float(value)
        if not math.isfinite(x):
            raise where.bad(key, value, self.describe(finite=True))
        inside = ((self.gt is None or x > self.gt) and (self.ge is None or x >= self.ge)
                  and (self.lt is None or x < self.lt) and (self.le is None or x <= self.le))
        if not inside:
            raise where.bad(key, value, self.describe())
        return x * factor(self.unit) if self.unit else x


@dataclass(frozen=True)
class Integer:
    """A TOML integer (not a float, not a boolean) in ``[ge, le]``."""

    ge: int | None = None
    le: int | None = None
    default: Any = REQUIRED

    def describe(self) -> str:
        if self.ge is not None and self.le is not None:
            return f"an integer {self.ge}-{self.le}"
        if self.ge is not None:
            return f"an integer at least {self.ge}"
        return f"an integer at most {self.le}" if self.le is not None else "an integer"

    def read(self, key: str, value: Any, where: Where) -> int:
        if not isinstance(value, int) or isinstance(value, bool):
            raise where.bad(key, value, f"int ({self.describe()})")
        if (self.ge is not None and value < self.ge) or (self.le is not None and value > self.le):
            raise where.bad(key, value, self.describe())
        return value


@dataclass(frozen=True)
class Text:
    """A TOML string, one of ``choices`` when given (each choice may carry a hint: ``{"total": "L_r"}``)."""

    choices: tuple[str, ...] | Mapping[str, str] = ()
    default: Any = REQUIRED

    def describe(self) -> str:
        if not self.choices:
            return "a string"
        hints = self.choices if isinstance(self.choices, Mapping) else {}
        return "one of " + ", ".join(f"{c} ({hints[c]})" if hints.get(c) else str(c) for c in self.choices)

    def read(self, key: str, value: Any, where: Where) -> str:
        if not isinstance(value, str):
            raise where.bad(key, value, f"str ({self.describe()})")
        if self.choices and value not in self.choices:
            raise where.bad(key, value, self.describe())
        return value


@dataclass(frozen=True)
class Flag:
    """A TOML boolean."""

    default: Any = REQUIRED

    def read(self, key: str, value: Any, where: Where) -> bool:
        if not isinstance(value, bool):
            raise where.bad(key, value, "bool (true or false)")
        return value


@dataclass(frozen=True)
class Numbers:
    """An array of numbers, each checked like ``item`` (and converted by its unit); ``length`` when fixed."""

    item: Number = Number()
    length: int | None = None
    default: Any = REQUIRED

    def read(self, key: str, value: Any, where: Where) -> tuple[float, ...]:
        count = f"{self.length} " if self.length is not None else ""
        expected = f"an array of {count}numbers, each {self.item.describe()}"
        if not isinstance(value, list) or (self.length is not None and len(value) != self.length):
            raise where.bad(key, value, expected)
        out = []
        for v in value:
            if not _is_number(v) or not math.isfinite(v):
                raise where.bad(key, value, expected)
            out.append(self.item.read(key, v, where))
        return tuple(out)


@dataclass(frozen=True)
class Table:
    """A sub-table, returned as is (read it with ``table()``/``read()`` at ``where.at(key)``)."""

    default: Any = REQUIRED

    def read(self, key: str, value: Any, where: Where) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise where.bad(key, value, "a table")
        return value


@dataclass(frozen=True)
class Tables:
    """An array of tables (``[[sensors]]``), returned as a list of dicts."""

    default: Any = REQUIRED

    def read(self, key: str, value: Any, where: Where) -> list[dict[str, Any]]:
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise where.bad(key, value, "an array of tables ([[" + where.path(key) + "]])")
        return value


@dataclass(frozen=True)
class Anything:
    """Any TOML value, unchecked (free-form provenance such as a rig's ``[calibration]``)."""

    default: Any = REQUIRED

    def read(self, key: str, value: Any, where: Where) -> Any:
        return value


Spec = Number | Integer | Text | Flag | Numbers | Table | Tables | Anything


PREFERRED_EDGE_UNITS: Mapping[str, str] = {"m": "mm", "rad": "mrad", "s": "ms", "pa": "gpa"}


def bounded(bounds: Mapping[str, tuple[float, float]], edge_units: Mapping[str, str] = PREFERRED_EDGE_UNITS, *,
            default: Any = None) -> dict[str, Spec]:
    """A schema for SI parameters with closed bounds, each read in its edge unit: ``{"tilt_rad": (0, 5e-3)}``
    gives the key ``tilt_mrad``, a number in [0, 5] converted to rad (a world effect's ``BOUNDS``, say)."""
    out: dict[str, Spec] = {}
    for si_key, (lo, hi) in bounds.items():
        unit = next((u for si, u in edge_units.items() if si_key.endswith(f"_{si}")), "")
        f = factor(unit) if unit else 1.0
        out[edge_name(si_key, unit) if unit else si_key] = Number(ge=lo / f, le=hi / f, unit=unit, default=default)
    return out


# ---- reading tables ------------------------------------------------------------------------------------------
def table(doc: Any, where: Where) -> dict[str, Any]:
    """``doc`` as a table, or an error naming where a table was expected."""
    if not isinstance(doc, dict):
        raise InputError(f"{where.file}: {where.table or 'document'} = {doc!r}: expected a table")
    return doc


def check_keys(doc: Mapping[str, Any], valid: Iterable[str], where: Where) -> None:
    """Refuse keys not in ``valid``, naming each one's closest valid key."""
    valid = set(valid)
    unknown = [k for k in doc if k not in valid]
    if unknown:
        raise where.unknown(unknown, valid)


def value_name(key: str, spec: Spec) -> str:
    """The name a key's value is returned under: its SI name for a number with an edge unit."""
    unit = spec.unit if isinstance(spec, Number) else spec.item.unit if isinstance(spec, Numbers) else ""
    return si_name(key, unit) if unit else key


def read(doc: Any, schema: Mapping[str, Spec], where: Where, *, unknown_ok: bool = False) -> dict[str, Any]:
    """Check a table against ``schema`` and return its values, numbers in SI under their SI names.

    Unknown keys are refused first (a typo is reported as a typo, not as the missing key it was meant to be);
    a key absent from the table takes its spec's default, or is an error if it has none (``REQUIRED``);
    a default of ``None`` leaves an optional key out of the result.
    """
    doc = table(doc, where)
    if not unknown_ok:
        check_keys(doc, schema, where)
    out: dict[str, Any] = {}
    for key, spec in schema.items():
        if key in doc:
            out[value_name(key, spec)] = spec.read(key, doc[key], where)
        elif spec.default is REQUIRED:
            raise where.missing(key, _describe(spec))
        elif spec.default is not None:  # defaults are written in the file's units, like the values
            out[value_name(key, spec)] = _default(spec)
    return out


def value(doc: Mapping[str, Any], key: str, spec: Spec, where: Where) -> Any:
    """One key of a table read against its spec (the default when absent; an error when required)."""
    if key in doc:
        return spec.read(key, doc[key], where)
    if spec.default is REQUIRED:
        raise where.missing(key, _describe(spec))
    return _default(spec)


def _default(spec: Spec) -> Any:
    if isinstance(spec, Number) and spec.unit and spec.default is not None:
        return spec.default * factor(spec.unit)
    return spec.default


def build(cls: type[T], doc: Any, schema: Mapping[str, Spec], where: Where, **given: Any) -> T:
    """A dataclass from a table: each schema key fills the field of its SI name; absent keys keep the field's
    default (a field without a plain default, or with a ``default_factory``, is required). ``given`` fills
    fields that do not come from the table. A ``ValueError`` raised by the dataclass itself (a rule across
    fields) becomes ``FILE: TABLE: ...``.
    """
    defaults = {f.name: f.default for f in fields(cls) if f.default is not MISSING}  # type: ignore[arg-type]
    full = {}
    for key, spec in schema.items():
        name = value_name(key, spec)
        if spec.default is REQUIRED and name in defaults:
            spec = _with_default(spec, None)
        full[key] = spec
    values = read(doc, full, where)
    try:
        return cls(**values, **given)
    except InputError:
        raise
    except ValueError as exc:
        raise where.problem(str(exc)) from None


def _with_default(spec: Spec, default: Any) -> Spec:
    return replace(spec, default=default)


def _describe(spec: Spec) -> str:
    if isinstance(spec, Number | Integer | Text):
        return spec.describe()
    if isinstance(spec, Numbers):
        return f"an array of numbers, each {spec.item.describe()}"
    if isinstance(spec, Table):
        return "a table"
    if isinstance(spec, Tables):
        return "an array of tables"
    return "a value"


def parse_toml(text: str, source: str) -> dict[str, Any]:
    """Parse TOML text; a syntax error names ``source`` (the file, or e.g. a campaign's stored copy)."""
    try:
        return tomllib.loads(text.removeprefix("\ufeff"))  # a UTF-8 byte-order mark is not content
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{source}: not valid TOML ({exc})") from None
