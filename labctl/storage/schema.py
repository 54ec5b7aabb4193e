"""Names and versions of the campaign file layout (documented in docs/storage.md), and how to walk it."""

from __future__ import annotations

from collections.abc import Iterator

import h5py

FORMAT = "labctl-campaign"
FORMAT_VERSION = 2
READABLE_VERSIONS = (1, 2)
CONFIG = "config"
FORCE = "force_n"
ACCEL = "accel_m_per_s2"
RESULT = "result"
CURVE = "curve"
COMPLETE = "complete"
FRF_MAX_HZ = 2000.0  # the stored FRF covers the paper's range of interest (the report plots up to here)
FRF_SPACING_HZ = 0.625  # the stored (display) FRF is thinned to about this spacing (40 lines per bounce bandwidth)
TRACE_CHUNK = 2048  # samples per chunk of a stored trace (the scale-offset filter packs each chunk)


def series_name(series: int) -> str:
    return f"series_{series:02d}"


def run_name(run: int) -> str:
    return f"run_{run:02d}"


def step_name(step: int) -> str:
    return f"step_{step:03d}"


def impact_name(attempt: int) -> str:
    return f"impact_{attempt:03d}"


def index_of(name: str) -> int:
    """The 1-based number at the end of a group name (``step_007`` → 7)."""
    return int(name.rsplit("_", 1)[1])


def number(group: h5py.Group) -> int:
    """The number of a series, run, step or impact group (``…/step_007`` → 7)."""
    return index_of(group.name.rsplit("/", 1)[-1])


def children(group: h5py.Group, prefix: str) -> list[h5py.Group]:
    """Sub-groups named ``<prefix>NN…`` (``series_``, ``run_``, ``step_``, ``impact_``) in number order."""
    return [group[k] for k in sorted(group) if k.startswith(prefix) and isinstance(group[k], h5py.Group)]


def all_runs(h5: h5py.File) -> Iterator[h5py.Group]:
    for series in children(h5, "series_"):
        yield from children(series, "run_")


def all_steps(h5: h5py.File) -> Iterator[h5py.Group]:
    for run in all_runs(h5):
        yield from children(run, "step_")


def stored_text(h5: h5py.File, name: str) -> str | None:
    """A configuration file's text kept under ``/config`` (None when the campaign has none of that name)."""
    cfg = h5.get(CONFIG)
    if cfg is None or name not in cfg:
        return None
    value = cfg[name][()]
    return value.decode() if isinstance(value, bytes) else str(value)
