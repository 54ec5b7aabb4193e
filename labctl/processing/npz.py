"""Reader for the impacts NPZ contract (docs/contracts.md): ``fs``, ``force``, ``accel``, ``channels``.

Loaded with ``allow_pickle=False``: a file that hides Python objects is refused, never executed. Before
anything is decompressed, every member's stated size and every array's header are checked against limits
(``MAX_NPZ_BYTES``, ``MAX_RATIO``), so a zip bomb or a header announcing terabytes is refused without
allocating; a damaged member (CRC error, bad deflate stream) is one line. Every error names the file, the
key and what was expected.
"""

from __future__ import annotations

import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np

from labctl.errors import InputError

KEYS = ("fs", "force", "accel", "channels")
MAX_NPZ_BYTES = 2**30
"""Largest uncompressed impacts NPZ read (a step of 10 blows, 16 channels, 262 144 samples is 0.35 GiB)."""
MAX_RATIO = 100.0
"""Largest compression ratio of a member above ``RATIO_FROM_BYTES``: measured samples (noise in every bit)
hardly compress; a member a hundred times smaller than it unpacks to is a zip bomb."""
RATIO_FROM_BYTES = 2**24


@dataclass(frozen=True)
class ImpactSet:
    """One load step's impacts: force (n_impacts, n_samples) N, accel (n_impacts, n_channels, n_samples) m/s²."""

    fs_hz: float
    force_n: np.ndarray
    accel_m_per_s2: np.ndarray
    channels: tuple[str, ...]
    source: str = ""


def _read(data: np.lib.npyio.NpzFile, key: str, where: str) -> np.ndarray:
    if key not in data.files:
        raise InputError(f"{where}: missing key '{key}' (an impacts NPZ holds {', '.join(KEYS)})")
    try:
        return data[key]
    except ValueError as exc:
        if "allow_pickle" in str(exc):
            raise InputError(f"{where}: key '{key}' holds pickled Python objects; expected a plain numeric or "
                             "string array (files are read with allow_pickle=False)") from None
        raise InputError(f"{where}: key '{key}' cannot be read ({exc})") from None
    except (zipfile.BadZipFile, zlib.error, OSError, EOFError) as exc:
        raise InputError(f"{where}: key '{key}' is damaged ({type(exc).__name__}: "
                         f"{' '.join(str(exc).split())[:120]})") from None


def _numeric(value: np.ndarray, key: str, ndim: int, layout: str, where: str) -> np.ndarray:
    if value.dtype.kind not in "iuf" or value.ndim != ndim:
        raise InputError(f"{where}: '{key}' has shape {value.shape} and dtype {value.dtype}; "
                         f"expected real numbers shaped {layout}")
    if value.size == 0:
        raise InputError(f"{where}: '{key}' is empty; expected {layout}")
    out = np.asarray(value, dtype=float)
    bad = ~np.isfinite(out)
    if bad.any():
        at = tuple(int(i) for i in np.argwhere(bad)[0])
        raise InputError(f"{where}: '{key}' holds a non-finite value at index {at}")
    return out


def _check_members(path: str | Path, where: str) -> None:
    """Refuse an NPZ whose members would unpack to more than the limits allow, or whose arrays' headers do
    not match their members' sizes, reading only the zip directory and each array's header."""
    try:
        with zipfile.ZipFile(path) as zf:
            infos = zf.infolist()
            total = sum(i.file_size for i in infos)
            if total > MAX_NPZ_BYTES:
                raise InputError(f"{where}: unpacks to {total / 2**20:.0f} MiB, more than the "
                                 f"{MAX_NPZ_BYTES / 2**20:.0f} MiB an impacts NPZ may hold")
            for info in infos:
                key = info.filename.removesuffix(".npy")
                if info.file_size > RATIO_FROM_BYTES and info.file_size > MAX_RATIO * max(info.compress_size, 1):
                    raise InputError(f"{where}: key '{key}' unpacks {info.file_size / info.compress_size:.0f}-fold "
                                     f"to {info.file_size / 2**20:.0f} MiB; refused as a zip bomb (measured "
                                     "samples do not compress like that)")
                with zf.open(info) as fh:
                    _check_header(fh, info, key, where)
    except zipfile.BadZipFile as exc:
        raise InputError(f"{where}: not a readable NPZ file ({exc})") from None
    except (OSError, EOFError, zlib.error) as exc:
        raise InputError(f"{where}: damaged NPZ file ({type(exc).__name__}: {exc})") from None


def _check_header(fh: IO[bytes], info: zipfile.ZipInfo, key: str, where: str) -> None:
    """An array member's header must announce exactly the bytes the member holds."""
    try:
        version = np.lib.format.read_magic(fh)
        if version == (1, 0):
            shape, _, dtype = np.lib.format.read_array_header_1_0(fh, max_header_size=10000)
        else:
            shape, _, dtype = np.lib.format.read_array_header_2_0(fh, max_header_size=10000)
    except (ValueError, SyntaxError) as exc:
        raise InputError(f"{where}: key '{key}' has no readable array header ({' '.join(str(exc).split())[:120]})"
                         ) from None
    count = 1
    for n in shape:
        count *= int(n)
    if dtype.hasobject:
        return  # refused with its own message when read (allow_pickle=False)
    data_bytes = count * dtype.itemsize
    if data_bytes > info.file_size:
        raise InputError(f"{where}: key '{key}' announces shape {shape} ({data_bytes / 2**20:.0f} MiB) but its "
                         f"member holds {info.file_size} bytes; damaged or crafted file")


def load_impacts_npz(path: str | Path) -> ImpactSet:
    """Read and validate an impacts NPZ; shapes must agree and channel names must be unique strings."""
    where = str(path)
    if Path(path).is_file() and zipfile.is_zipfile(path):
        _check_members(path, where)
    try:
        data = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise InputError(f"{where}: file not found") from None
    except IsADirectoryError:
        raise InputError(f"{where}: is a directory, expected an impacts .npz file") from None
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as exc:
        raise InputError(f"{where}: not a readable NPZ file ({type(exc).__name__})") from None
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise InputError(f"{where}: holds a single array, expected an NPZ archive with keys {', '.join(KEYS)}")
    with data:
        fs = _read(data, "fs", where)
        force = _read(data, "force", where)
        accel = _read(data, "accel", where)
        names = _read(data, "channels", where)
    if fs.size != 1 or fs.dtype.kind not in "iuf" or not np.isfinite(fs).all() or not float(fs.ravel()[0]) > 0:
        raise InputError(f"{where}: 'fs' = {fs.tolist()!r}; expected one positive sample rate in Hz")
    force = _numeric(force, "force", 2, "(n_impacts, n_samples)", where)
    accel = _numeric(accel, "accel", 3, "(n_impacts, n_channels, n_samples)", where)
    if accel.shape[0] != force.shape[0] or accel.shape[2] != force.shape[1]:
        raise InputError(f"{where}: 'accel' has shape {accel.shape} but 'force' has {force.shape}; expected "
                         f"accel shaped ({force.shape[0]}, n_channels, {force.shape[1]})")
    if names.dtype.kind != "U" or names.ndim != 1:
        raise InputError(f"{where}: 'channels' has shape {names.shape} and dtype {names.dtype}; expected a 1-D "
                         "array of channel names such as 'A1X'")
    channels = tuple(str(c) for c in names)
    if len(channels) != accel.shape[1]:
        raise InputError(f"{where}: 'channels' names {len(channels)} channels but 'accel' has {accel.shape[1]}")
    if len(set(channels)) != len(channels):
        dup = sorted({c for c in channels if channels.count(c) > 1})
        raise InputError(f"{where}: 'channels' repeats {', '.join(dup)}; expected unique names")
    return ImpactSet(float(fs.ravel()[0]), force, accel, channels, where)
