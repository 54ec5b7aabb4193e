"""Data files shipped with labctl (material and roller catalogues, rig descriptions, world scenarios) and the one
way configuration files are read: ``labctl.data.schema`` (typed keys, one error format) and ``labctl.data.units``
(edge units to SI)."""

from __future__ import annotations

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
