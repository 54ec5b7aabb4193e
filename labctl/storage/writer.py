"""Write a campaign file impact by impact; every write is flushed so a crash loses at most the impact in flight.

HDF5 keeps changed metadata in memory until a flush, so a process killed between flushes leaves the file as
it was at the last flush. Each group gets ``complete = True`` as its last write; resume deletes groups
without it.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from labctl import __version__
from labctl.errors import InputError
from labctl.storage import schema as s


def utc_now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def _attrs(obj: h5py.Group | h5py.Dataset, values: Mapping[str, Any]) -> None:
    for key, value in values.items():
        if value is None:
            continue
        if isinstance(value, list | tuple | dict) and not (isinstance(value, list | tuple) and value
                                                             and all(isinstance(v, int | float) for v in value)):
            value = json.dumps(value)
        obj.attrs[key] = value


@dataclass(frozen=True)
class ImpactData:
    """What the engine hands to storage for one blow: raw traces, calibration and the check's verdict."""

    sample_rate_hz: float
    force_n: np.ndarray
    accel_m_per_s2: np.ndarray
    channels: tuple[str, ...]
    trigger_index: int
    timestamp_s: float
    accepted: bool
    reasons: tuple[str, ...]
    peak_force_n: float
    pulse_width_s: float
    clipped: tuple[str, ...]
    force_calibration: Mapping[str, Any]
    channel_calibration: Mapping[str, Any]


class CampaignWriter:
    """An open campaign file; create a new one with ``create`` or continue one with ``open_existing``."""

    def __init__(self, h5: h5py.File) -> None:
        self.h5 = h5
        self.path = str(h5.filename)

    @classmethod
    def create(cls, path: str | Path, *, protocol_name: str, backend: str, seed: int | None,
               config_files: Mapping[str, str], description: Mapping[str, Any]) -> CampaignWriter:
        """A new file (refusing to overwrite an existing one)."""
        p = Path(path)
        if p.exists():
            raise InputError(f"{p}: already exists; use --resume to continue it or choose another --out")
        p.parent.mkdir(parents=True, exist_ok=True)
        h5 = h5py.File(p, "w")
        _attrs(h5, {"format": s.FORMAT, "format_version": s.FORMAT_VERSION, "software_version": __version__,
                    "created_utc": utc_now(), "backend": backend, "protocol_name": protocol_name,
                    "seed": -1 if seed is None else seed, "status": "running",
                    "backend_description": dict(description)})
        cfg = h5.create_group(s.CONFIG)
        for name, text in config_files.items():
            cfg.create_dataset(name, data=text, dtype=h5py.string_dtype())
        h5.flush()
        return cls(h5)

    @classmethod
    def open_existing(cls, path: str | Path) -> CampaignWriter:
        """Reopen a campaign to continue it; partial groups left by a crash are removed."""
        p = Path(path)
        if not p.exists():
            raise InputError(f"{p}: no campaign file to resume")
        try:
            h5 = h5py.File(p, "r+")
        except OSError as exc:
            raise InputError(f"{p}: cannot open the campaign file for resuming ({exc})") from None
        if h5.attrs.get("format") != s.FORMAT:
            h5.close()
            raise InputError(f"{p}: not a labctl campaign file")
        writer = cls(h5)
        writer._drop_incomplete()
        h5.attrs["status"] = "running"
        h5.attrs["resumed_utc"] = utc_now()
        h5.flush()
        return writer

    def _drop_incomplete(self) -> None:
        for run in list(s.all_runs(self.h5)):
            for step in s.children(run, "step_"):
                for group in [*s.children(step, "impact_"), step.get(s.RESULT)]:
                    if group is not None and not group.attrs.get(s.COMPLETE, False):
                        del self.h5[group.name]
            curve = run.get(s.CURVE)
            if curve is not None and not curve.attrs.get(s.COMPLETE, False):
                del self.h5[curve.name]

    def config_text(self, name: str) -> str | None:
        return s.stored_text(self.h5, name)

    def _group(self, *names: str, attrs: Mapping[str, Any] | None = None) -> h5py.Group:
        g = self.h5
        for n in names:
            g = g.require_group(n)
        if attrs and not g.attrs.get("created_utc"):
            _attrs(g, {**attrs, "created_utc": utc_now()})
            self.h5.flush()
        return g

    def series(self, series: int, specimen: Mapping[str, Any]) -> h5py.Group:
        return self._group(s.series_name(series), attrs=specimen)

    def run(self, series: int, run: int) -> h5py.Group:
        return self._group(s.series_name(series), s.run_name(run), attrs={"repetition": run})

    def step(self, series: int, run: int, step: int, attrs: Mapping[str, Any]) -> h5py.Group:
        """The step's group; its attributes (knob angle, load) are set when it is first created."""
        return self._group(s.series_name(series), s.run_name(run), s.step_name(step), attrs={"step": step, **attrs})

    def update_step(self, series: int, run: int, step: int, attrs: Mapping[str, Any]) -> None:
        _attrs(self.h5[s.series_name(series)][s.run_name(run)][s.step_name(step)], attrs)
        self.h5.flush()

    def write_impact(self, series: int, run: int, step: int, attempt: int, data: ImpactData) -> None:
        """Store one blow (accepted or not) and flush; ``complete`` is written last."""
        g = self.h5[s.series_name(series)][s.run_name(run)][s.step_name(step)].create_group(s.impact_name(attempt))
        f = g.create_dataset(s.FORCE, data=np.asarray(data.force_n, dtype=np.float32))
        _attrs(f, {"unit": "N", **data.force_calibration})
        a = g.create_dataset(s.ACCEL, data=np.asarray(data.accel_m_per_s2, dtype=np.float32),
                             chunks=(1, data.accel_m_per_s2.shape[-1]))
        _attrs(a, {"unit": "m/s^2", "channels": list(data.channels), **data.channel_calibration})
        _attrs(g, {"attempt": attempt, "accepted": bool(data.accepted), "reasons": list(data.reasons),
                   "peak_force_n": data.peak_force_n, "pulse_width_s": data.pulse_width_s,
                   "sample_rate_hz": data.sample_rate_hz, "trigger_index": data.trigger_index,
                   "timestamp_utc": datetime.fromtimestamp(data.timestamp_s, UTC).isoformat(timespec="milliseconds"),
                   "clipped": list(data.clipped)})
        g.attrs[s.COMPLETE] = True
        self.h5.flush()

    def write_step_result(self, series: int, run: int, step: int, summary: Mapping[str, Any],
                          frequencies_hz: np.ndarray | None = None, h1: np.ndarray | None = None,
                          coherence: np.ndarray | None = None) -> None:
        """Store a step's modal result (and its FRF up to ``FRF_MAX_HZ``), then mark the step complete."""
        stg = self.h5[s.series_name(series)][s.run_name(run)][s.step_name(step)]
        if s.RESULT in stg:
            del stg[s.RESULT]
        g = stg.create_group(s.RESULT)
        if frequencies_hz is not None and h1 is not None:
            keep = frequencies_hz <= s.FRF_MAX_HZ
            g.create_dataset("frequencies_hz", data=frequencies_hz[keep])
            g.create_dataset("h1", data=np.asarray(h1)[..., keep].astype(np.complex64))
            if coherence is not None:
                g.create_dataset("coherence", data=np.asarray(coherence)[..., keep].astype(np.float32))
        _attrs(g, dict(summary))
        g.attrs[s.COMPLETE] = True
        stg.attrs[s.COMPLETE] = True
        self.h5.flush()

    def write_curve(self, series: int, run: int, columns: Mapping[str, np.ndarray]) -> None:
        """Store a repetition's stiffness-vs-load table and mark the run complete."""
        rg = self.h5[s.series_name(series)][s.run_name(run)]
        if s.CURVE in rg:
            del rg[s.CURVE]
        g = rg.create_group(s.CURVE)
        for name, values in columns.items():
            g.create_dataset(name, data=np.asarray(values, dtype=float))
        g.attrs[s.COMPLETE] = True
        rg.attrs[s.COMPLETE] = True
        rg.attrs["finished_utc"] = utc_now()
        self.h5.flush()

    def set_status(self, status: str, message: str = "") -> None:
        self.h5.attrs["status"] = status
        self.h5.attrs["status_message"] = message
        self.h5.attrs["status_utc"] = utc_now()
        self.h5.flush()

    def close(self) -> None:
        if self.h5.id.valid:
            self.h5.flush()
            self.h5.close()

    def __enter__(self) -> CampaignWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
