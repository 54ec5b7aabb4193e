"""A campaign file is read only if it is made of what labctl's writer makes.

Lab files travel between people, and HDF5 can point outside the file: a dataset's data may live in another
file (external storage), be assembled from other files (virtual datasets), or a link may name another file
(external links), and a filter may load a plug-in. Reading such a file would disclose, or run, something
that is not in it. ``check_structure`` walks every link once without following any, and refuses anything
but hard links to groups and datasets stored in the file with the writer's filters, with one line naming
the object. The per-value checks (``number_attr``) refuse attributes of the wrong type or shape where they
are read.
"""

from __future__ import annotations

import math
from typing import Any

import h5py
import numpy as np
from h5py import h5d, h5l, h5o, h5z

from labctl.errors import InputError

ALLOWED_FILTERS = {h5z.FILTER_DEFLATE: "gzip", h5z.FILTER_SHUFFLE: "shuffle", h5z.FILTER_SCALEOFFSET: "scaleoffset",
                   h5z.FILTER_FLETCHER32: "fletcher32", 32000: "lzf"}
"""Filters labctl's writers use (and the two h5py builds in); any other would be a plug-in loaded to read."""
MAX_OBJECTS = 2_000_000
"""More links than this is not a campaign file (a 60-step, 3-repetition campaign has about 2 000)."""


def _where(path: object, name: str) -> str:
    return f"{path}:/{name}"


def _text(raw: bytes | str) -> str:
    return raw.decode("utf-8", "replace") if isinstance(raw, bytes) else raw


def _check_layout(dataset: h5d.DatasetID, where: str) -> None:
    """Refuse a dataset whose data is outside the file (external storage, virtual) or behind a filter
    labctl does not write."""
    plist = dataset.get_create_plist()
    if plist.get_layout() == h5d.VIRTUAL:
        raise InputError(f"{where}: a virtual dataset (its data comes from other files); labctl reads only "
                         "data stored in the campaign file")
    if plist.get_external_count() > 0:
        raise InputError(f"{where}: its data is stored in the external file {_text(plist.get_external(0)[0])!r}; "
                         "labctl reads only data stored in the campaign file")
    for i in range(plist.get_nfilters()):
        code = plist.get_filter(i)[0]
        if code not in ALLOWED_FILTERS:
            raise InputError(f"{where}: stored with HDF5 filter {code}, which labctl does not write "
                             f"(expected {', '.join(sorted(ALLOWED_FILTERS.values()))})")


def check_structure(h5: h5py.File, path: object = None) -> None:
    """Walk every link of the file without following one; refuse soft, external and user-defined links, and
    datasets ``_check_layout`` refuses. Reads no data. The walk is HDF5's own link iteration with each link's
    type (h5py's high-level walk looks every name up again: five times slower on a campaign file)."""
    shown = path if path is not None else h5.filename
    count = 0

    def problem(name: bytes, info: Any) -> InputError | None:
        where = _where(shown, _text(name))
        if info.type == h5l.TYPE_EXTERNAL:
            filename, target = h5.id.links.get_val(name)
            return InputError(f"{where}: an external link to {_text(filename)}:{_text(target)}; labctl reads only "
                              "objects stored in the campaign file")
        if info.type == h5l.TYPE_SOFT:
            return InputError(f"{where}: a soft link to {_text(h5.id.links.get_val(name))}; labctl's writer makes "
                              "none")
        if info.type != h5l.TYPE_HARD:
            return InputError(f"{where}: a user-defined link (type {info.type}); labctl's writer makes none")
        obj = h5o.open(h5.id, name)
        if isinstance(obj, h5d.DatasetID):
            try:
                _check_layout(obj, where)
            except InputError as exc:
                return exc
        return None

    def visit(name: bytes, info: Any) -> Exception | None:  # a non-None return ends the walk, and is raised
        nonlocal count                                         # after it: no exception may cross HDF5's iteration
        count += 1
        if count > MAX_OBJECTS:
            return InputError(f"{shown}: more than {MAX_OBJECTS} objects; not a campaign file")
        try:
            return problem(name, info)
        except Exception as exc:  # noqa: BLE001 - e.g. a link half-written by a running campaign (a live read)
            return exc

    found = h5.id.links.visit(visit, info=True)
    if found is not None:
        raise found


def number_attr(obj: h5py.Group | h5py.Dataset, name: str, *, size: int | None = None, default: Any = None,
                finite: bool = True) -> np.ndarray | None:
    """A numeric attribute as a float array (a scalar as shape ()), checked: numbers only, ``size`` values
    when given, finite when asked. None (or ``default``) when absent."""
    if name not in obj.attrs:
        return default
    raw = obj.attrs[name]
    where = f"{obj.file.filename}:{obj.name} attribute {name!r}"
    arr = np.asarray(raw)
    if arr.dtype.kind not in "iuf" or arr.ndim > 1:
        raise InputError(f"{where}: expected {'a number' if size in (None, 1) else f'{size} numbers'}, found "
                         f"{_describe(raw)}")
    values = arr.astype(float)
    if size is not None and values.size != size and not (size == 1 and values.size == 1):
        raise InputError(f"{where}: expected {size} value(s), found {values.size}")
    if finite and not np.all(np.isfinite(values)):
        bad = next(v for v in np.atleast_1d(values) if not math.isfinite(v))
        raise InputError(f"{where}: {bad} is not a finite number")
    return values


def _describe(value: Any) -> str:
    arr = np.asarray(value)
    text = repr(value.decode() if isinstance(value, bytes) else value)
    return f"{arr.dtype.kind!r}-typed {text[:40]}"
