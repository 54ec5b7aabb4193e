"""The spring characterisation file: a small HDF5 file of knob angles and loads (``kind`` names it)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import h5py
import numpy as np

from labctl.errors import InputError

KIND = "spring_characterisation"
DATASETS = ("angle_deg", "load_n", "direction")


def write_spring_file(path: str | Path, arrays: Mapping[str, np.ndarray], attrs: Mapping[str, str]) -> None:
    """Write the readings and their text attributes; an existing file is never overwritten."""
    p = Path(path)
    if p.exists():
        raise InputError(f"{p}: exists; a characterisation never overwrites a file (choose another --out)")
    with h5py.File(p, "x") as f:
        f.attrs.update({"kind": KIND, **attrs})
        for name in DATASETS:
            f.create_dataset(name, data=np.asarray(arrays[name]))


def read_spring_file(path: str | Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """The readings and text attributes of a characterisation file; anything else is an InputError."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: spring characterisation file not found")
    try:
        with h5py.File(p, "r") as f:
            if f.attrs.get("kind") != KIND:
                raise InputError(f"{p}: not a spring characterisation file (kind {f.attrs.get('kind')!r}, "
                                 f"expected {KIND!r})")
            missing = [n for n in DATASETS if n not in f]
            if missing:
                raise InputError(f"{p}: missing dataset(s) {', '.join(missing)}")
            return ({n: f[n][()] for n in DATASETS},
                    {k: str(v) for k, v in f.attrs.items() if k != "kind"})
    except OSError as exc:
        raise InputError(f"{p}: cannot read as HDF5 ({exc})") from None
