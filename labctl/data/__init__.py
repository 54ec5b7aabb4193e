"""Data files shipped with labctl (material and roller catalogues, rig descriptions, world scenarios) and the one
way configuration files are read: ``labctl.data.schema`` (typed keys, one error format) and ``labctl.data.units``
(edge units to SI)."""

from __future__ import annotations

import math
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any

from labctl.errors import InputError


def data_path(name: str) -> Path:
    """Path of a shipped data file, e.g. ``data_path("rigs/paper_rig.toml")``."""
    return Path(str(resources.files("labctl.data").joinpath(name)))


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file; a missing file or a syntax error becomes an InputError naming the file."""
    p = Path(path)
    try:
        with p.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise InputError(f"{p}: file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{p}: not valid TOML ({exc})") from None
    except IsADirectoryError:
        raise InputError(f"{p}: is a directory, expected a TOML file") from None


def require(table: dict[str, Any], key: str, kind: type | tuple[type, ...], where: str) -> Any:
    """Fetch ``table[key]`` and check its type, with an error naming ``where.key`` (a float must be finite).

    Kept for readers not yet on ``labctl.data.schema`` (whose ``read``/``build`` new code should use).
    """
    if key not in table:
        raise InputError(f"{where}: missing key '{key}'")
    value = table[key]
    kinds = kind if isinstance(kind, tuple) else (kind,)
    if float in kinds and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if isinstance(value, bool) and bool not in kinds or not isinstance(value, kinds):
        names = " or ".join(k.__name__ for k in kinds)
        raise InputError(f"{where}.{key} = {value!r}: expected {names}")
    if isinstance(value, float) and not math.isfinite(value):
        raise InputError(f"{where}.{key} = {value!r}: expected a finite number")
    return value


def positive(table: dict[str, Any], key: str, where: str) -> float:
    """Fetch a strictly positive number."""
    value = require(table, key, float, where)
    if not value > 0:
        raise InputError(f"{where}.{key} = {value!r}: expected a positive number")
    return value
