"""Data files shipped with labctl (material and roller catalogues, rig descriptions, world scenarios) and the one
way configuration files are read: ``labctl.data.schema`` (typed keys, one error format) and ``labctl.data.units``
(edge units to SI)."""

from __future__ import annotations

import tomllib
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any

from labctl.errors import InputError


@cache
def data_path(name: str) -> Path:
    """Path of a shipped data file, e.g. ``data_path("rigs/paper_rig.toml")`` (looked up once per name: the
    catalogues ask for theirs at every roller and material they resolve)."""
    return Path(str(resources.files("labctl.data").joinpath(name)))


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file; a missing or unreadable file, text that is not UTF-8 or a syntax error becomes an
    InputError naming the file. A UTF-8 byte-order mark (as some Windows editors write) is accepted."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise InputError(f"{p}: file not found") from None
    except IsADirectoryError:
        raise InputError(f"{p}: is a directory, expected a TOML file") from None
    except OSError as exc:
        raise InputError(f"{p}: cannot be read ({exc.strerror or exc})") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"{p}: not UTF-8 text (byte {exc.start}); save the file as UTF-8") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{p}: not valid TOML ({exc})") from None
