"""Write a campaign file impact by impact; every write is flushed so a crash loses at most the impact in flight.

A process killed at any moment, inside a flush too, leaves the file as of its last flush (its rollback journal,
``labctl.storage.rollback``). Each group gets ``complete = True`` as its last write; resume deletes groups
without it. Before each impact the writer reserves room for it (``labctl.storage.diskspace``); a write that
fails anyway (disk full, file-size limit, I/O error) is undone to the last flush, the partial impact dropped
and ``DiskFull`` raised, so the campaign stays processable and resumable.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import fields, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import h5py

from labctl import __version__
from labctl.errors import InputError
from labctl.stiffness_table import StiffnessPoint
from labctl.storage import schema as s
from labctl.storage.diskspace import DiskFull, discard, trim
from labctl.storage.encode import _attrs, _write_trace, impact_attrs, write_frf
from labctl.storage.guard import WriteGuard, guarded
from labctl.storage.inuse import clear_writer, in_use_message, is_lock_error, mark_writer
from labctl.storage.reader import attrs_of, complete_impacts, curves_of, impact_info, impact_record, processed_steps
from labctl.storage.records import (
    ImpactInfo,
    ImpactRecord,
    RepetitionCurve,
    StepResult,
    Verdict,
    curve_from_steps,
)
from labctl.storage.rollback import FileInUse, JournaledFile
from labctl.storage.runlog import LogEntry, append_entry, read_entries
from labctl.storage.safety import check_structure
from labctl.storage.specimen import SpecimenRecord
from labctl.storage.store import StepRow, StepStamp, first_impact_s


def utc_now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


IMPACT_SLACK_BYTES = 256 * 2**10
"""An impact's metadata beyond its samples (group, two dataset headers, chunk index, attributes), generously."""


class CampaignWriter(WriteGuard):
    """An open campaign file; create a new one with ``create`` or continue one with ``open_existing``."""

    def __init__(self, h5: h5py.File) -> None:
        self.h5 = h5
        self.path = str(h5.filename)
        self._accepted: int | None = None  # accepted impacts in the file, counted once then kept up to date
        self._infos: dict[tuple[int, int, int], list[ImpactInfo]] = {}  # per step: read once, then kept current

    @classmethod
    def create(cls, path: str | Path, *, protocol_name: str, backend: str, seed: int | None,
               config_files: Mapping[str, str], description: Mapping[str, Any]) -> CampaignWriter:
        """A new file (refusing to overwrite an existing one).

        The file is made under a temporary name and renamed when its root attributes and configuration are
        flushed, so a crash during creation leaves no campaign file that cannot be opened or resumed."""
        p = Path(path)
        if p.exists():
            raise InputError(f"{p}: already exists; use --resume to continue it or choose another --out")
        tmp = p.with_name(f".{p.name}.creating")
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
            h5 = h5py.File(tmp, "w")  # a leftover of a crashed creation is ours to replace
        except OSError as exc:
            raise InputError(f"{p}: cannot create the campaign file ({exc.strerror or exc})") from None
        try:
            cls._initialise(h5, protocol_name=protocol_name, backend=backend, seed=seed, config_files=config_files,
                            description=description)
            h5.close()
            if p.exists():
                raise InputError(f"{p}: already exists; use --resume to continue it or choose another --out")
            os.replace(tmp, p)
        except BaseException:
            discard(h5)
            tmp.unlink(missing_ok=True)
            raise
        try:
            writer = cls(JournaledFile(p))
        except OSError as exc:
            raise InputError(f"{p}: cannot open the new campaign file ({exc.strerror or exc})") from None
        mark_writer(p)
        return writer

    @staticmethod
    def _initialise(h5: h5py.File, *, protocol_name: str, backend: str, seed: int | None,
                    config_files: Mapping[str, str], description: Mapping[str, Any]) -> None:
        _attrs(h5, {"format": s.FORMAT, "format_version": s.FORMAT_VERSION, "software_version": __version__,
                    "created_utc": utc_now(), "backend": backend, "protocol_name": protocol_name,
                    "seed": -1 if seed is None else seed, "status": "running",
                    "backend_description": dict(description)})
        cfg = h5.create_group(s.CONFIG)
        for name, text in config_files.items():
            cfg.create_dataset(name, data=text, dtype=h5py.string_dtype())
        h5.flush()

    @classmethod
    def open_existing(cls, path: str | Path) -> CampaignWriter:
        """Reopen a campaign to continue it; partial groups left by a crash are removed."""
        p = Path(path)
        if not p.exists():
            raise InputError(f"{p}: no campaign file to resume")
        try:
            h5 = JournaledFile(p)  # a journal left by a writer killed in a flush is rolled back here
        except (FileInUse, OSError) as exc:
            busy = isinstance(exc, FileInUse) or is_lock_error(exc)
            raise InputError(in_use_message(p) if busy else f"{p}: cannot open the campaign file for resuming "
                             f"({exc})") from None
        if h5.attrs.get("format") != s.FORMAT:
            h5.close()
            raise InputError(f"{p}: not a labctl campaign file")
        if h5.attrs.get("format_version") != s.FORMAT_VERSION:
            version = h5.attrs.get("format_version")
            h5.close()
            raise InputError(f"{p}: written with campaign format {version}; --resume continues only format "
                             f"{s.FORMAT_VERSION} files (process, report and export still read it)")
        try:
            check_structure(h5, p)
        except BaseException:
            h5.close()
            raise
        writer = cls(h5)
        mark_writer(p)
        writer._drop_incomplete()
        h5.attrs["status"] = "running"
        h5.attrs["resumed_utc"] = utc_now()
        h5.flush()
        return writer

    def config_text(self, name: str) -> str | None:
        return s.stored_text(self.h5, name)

    @property
    def attrs(self) -> dict[str, Any]:
        return attrs_of(self.h5)

    def has_series(self) -> bool:
        return any(k.startswith("series_") for k in self.h5)

    @guarded
    def _group(self, *names: str, attrs: Mapping[str, Any] | None = None) -> h5py.Group:
        g = self.h5
        for n in names:
            g = g.require_group(n)
        if attrs and not g.attrs.get("created_utc"):
            _attrs(g, {**attrs, "created_utc": utc_now()})
            self.h5.flush()
        return g

    def _step_group(self, series: int, run: int, step: int) -> h5py.Group | None:
        return self.h5.get(f"{s.series_name(series)}/{s.run_name(run)}/{s.step_name(step)}")

    def series(self, series: int, specimen: SpecimenRecord) -> None:
        """The specimen's group; its attributes are set when it is first created."""
        self._group(s.series_name(series), attrs=specimen.attrs())

    def is_mounted(self, series: int) -> bool:
        g = self.h5.get(s.series_name(series))
        return bool(g is not None and g.attrs.get("mounted", False))

    @guarded
    def mark_mounted(self, series: int) -> None:
        self.h5[s.series_name(series)].attrs["mounted"] = True
        self.h5.flush()

    def complete_runs(self, series: int) -> set[int]:
        g = self.h5.get(s.series_name(series))
        return set() if g is None else {s.number(r) for r in s.children(g, "run_") if r.attrs.get(s.COMPLETE)}

    def run_started(self, series: int, run: int) -> bool:
        return f"{s.series_name(series)}/{s.run_name(run)}" in self.h5

    def run(self, series: int, run: int) -> None:
        self._group(s.series_name(series), s.run_name(run), attrs={"repetition": run})

    def step(self, series: int, run: int, step: int, attrs: Mapping[str, Any]) -> None:
        """The step's group; its attributes (knob angle, load) are set when it is first created."""
        self._group(s.series_name(series), s.run_name(run), s.step_name(step), attrs={"step": step, **attrs})

    def step_load(self, series: int, run: int, step: int, *, complete_only: bool = False) -> float | None:
        """The recorded load per roller of a step (None: not recorded yet, or not complete when asked)."""
        g = self._step_group(series, run, step)
        if g is None or "load_n" not in g.attrs or (complete_only and not g.attrs.get(s.COMPLETE, False)):
            return None
        return float(g.attrs["load_n"])

    @guarded
    def update_step(self, series: int, run: int, step: int, attrs: Mapping[str, Any]) -> None:
        _attrs(self.h5[s.series_name(series)][s.run_name(run)][s.step_name(step)], attrs)
        self.h5.flush()

    def step_attrs(self, series: int, run: int, step: int) -> dict[str, Any]:
        """A stored step's attributes (empty when the step is not stored)."""
        g = self._step_group(series, run, step)
        return {} if g is None else attrs_of(g)

    def impact_infos(self, series: int, run: int, step: int) -> list[ImpactInfo]:
        key = (series, run, step)  # asked before every blow: the writer's own writes keep the list current
        if key not in self._infos and (g := self._step_group(series, run, step)) is not None:
            self._infos[key] = [impact_info(ig) for ig in complete_impacts(g)]
        return list(self._infos.get(key, []))

    def impacts(self, series: int, run: int, step: int) -> list[ImpactRecord]:
        """The step's complete impacts as stored (read back, so live processing sees what reprocessing will)."""
        g = self._step_group(series, run, step)
        return [] if g is None else [impact_record(ig) for ig in complete_impacts(g)]

    def accepted_count(self) -> int:
        """Impacts accepted so far over the whole campaign (what progress counts)."""
        if self._accepted is None:
            self._accepted = sum(bool(ig.attrs.get("accepted")) for st in s.all_steps(self.h5)
                                 for ig in complete_impacts(st))
        return self._accepted

    def write_impact(self, series: int, run: int, step: int, record: ImpactRecord) -> ImpactRecord:
        """Store one blow (accepted or not) and flush; ``complete`` is written last. Returns the record as a
        reader will read it back (traces at their stored precision), so the caller needs no read-back.

        Raises DiskFull before writing when there is no room for it (with the reserve), and after a failed
        write, with the file reopened as of the previous impact."""
        self.ensure_room(4 * (record.force_n.size + record.accel_m_per_s2.size) + IMPACT_SLACK_BYTES)
        with self._writing():
            return self._write_impact(series, run, step, record)

    def _write_impact(self, series: int, run: int, step: int, record: ImpactRecord) -> ImpactRecord:
        g = self.h5[s.series_name(series)][s.run_name(run)][s.step_name(step)].create_group(
            s.impact_name(record.attempt))
        cal, info = record.calibration, record.info
        f, force_n = _write_trace(g, s.FORCE, record.force_n, [cal.force_range_n])
        _attrs(f, {"unit": "N", "sensitivity_v_per_unit": cal.force_sensitivity_v_per_n,
                   "range_units": cal.force_range_n})
        n_ch = len(record.channels)
        a, accel = _write_trace(g, s.ACCEL, record.accel_m_per_s2, list(cal.accel_range_m_per_s2 or [None] * n_ch))
        _attrs(a, {"unit": "m/s^2", "channels": list(record.channels),
                   "sensitivity_v_per_unit": cal.accel_sensitivity_v_per_m_per_s2,
                   "range_units": cal.accel_range_m_per_s2})
        if self._accepted is not None:
            self._accepted += int(info.verdict.accepted)
        _attrs(g, impact_attrs(record))
        g.attrs[s.COMPLETE] = True
        self.h5.flush()
        self._infos.get((series, run, step), []).append(info)
        return replace(record, force_n=force_n, accel_m_per_s2=accel)

    def _verdict(self, g: h5py.Group, verdict: Verdict) -> ImpactInfo:
        """Write the verdict and return the impact's info as a reader will read it (the reasons attribute is
        rewritten from it: the checks' reasons are read without the operator's, so it does not change them)."""
        if self._accepted is not None:
            self._accepted += int(verdict.accepted) - int(bool(g.attrs.get("accepted", False)))
        g.attrs["accepted"] = bool(verdict.accepted)
        g.attrs["verdict_source"] = verdict.source
        g.attrs["verdict_reason"] = verdict.reason
        info = impact_info(g)
        g.attrs["reasons"] = json.dumps(list(info.reasons))
        return info

    @guarded
    def set_verdict(self, series: int, run: int, step: int, attempt: int, verdict: Verdict) -> None:
        """Record the operator's (or the checks') verdict on a stored impact and flush."""
        g = self.h5[s.series_name(series)][s.run_name(run)][s.step_name(step)][s.impact_name(attempt)]
        info = self._verdict(g, verdict)
        self.h5.flush()
        infos = self._infos.get((series, run, step), [])
        infos[:] = [info if i.attempt == attempt else i for i in infos]

    @guarded
    def write_step_result(self, series: int, run: int, step: int, result: StepResult) -> None:
        """Store a step's result (and its FRF up to ``FRF_MAX_HZ``), then mark the step complete."""
        stg = self.h5[s.series_name(series)][s.run_name(run)][s.step_name(step)]
        if s.RESULT in stg:
            del stg[s.RESULT]
        g = stg.create_group(s.RESULT)
        if result.frf is not None:
            write_frf(g, result.frf)
        _attrs(g, {f.name: getattr(result, f.name) for f in fields(result) if f.name != "frf"})
        if result.error:
            stg.attrs["failed"] = result.error
        g.attrs[s.COMPLETE] = True
        stg.attrs[s.COMPLETE] = True
        self.h5.flush()

    @guarded
    def complete_step(self, series: int, run: int, step: int) -> None:
        """Mark a step complete without a hammer result (a static-only step)."""
        self.h5[s.series_name(series)][s.run_name(run)][s.step_name(step)].attrs[s.COMPLETE] = True
        self.h5.flush()

    def step_results(self, series: int, run: int) -> list[tuple[int, float, float, StepResult]]:
        """(step, load, knob angle, result) of a repetition's processed steps, in step order."""
        return processed_steps(self.h5[s.series_name(series)][s.run_name(run)])

    def run_attrs(self, series: int, run: int) -> dict[str, Any]:
        """A repetition's attributes (decoded), e.g. the load steps an adaptive campaign added to it."""
        g = self.h5.get(f"{s.series_name(series)}/{s.run_name(run)}")
        return {} if g is None else attrs_of(g)

    @guarded
    def set_run_attrs(self, series: int, run: int, attrs: Mapping[str, Any]) -> None:
        """Set attributes of a started repetition (nested values are stored as JSON)."""
        _attrs(self.h5[f"{s.series_name(series)}/{s.run_name(run)}"], attrs)
        self.h5.flush()

    def stiffness_points(self) -> list[StiffnessPoint]:
        """The identified steps measured so far in this file, as stiffness table rows (what a planner needs)."""
        points: list[StiffnessPoint] = []
        for sg in s.children(self.h5, "series_"):
            spec = SpecimenRecord.from_attrs(attrs_of(sg))
            for rg in s.children(sg, "run_"):
                for step, load, _, result in self.step_results(s.number(sg), s.number(rg)):
                    if result.identified:
                        points.append(spec.point(s.number(rg), load, result.roller_stiffness_n_per_m, result,
                                                 attrs_of(rg[s.step_name(step)]).get("load_std_n")))
        return points

    @guarded
    def store_curve(self, series: int, run: int, steps: list[StepRow] | None = None) -> RepetitionCurve:
        """Store and return a repetition's stiffness-vs-load table (from ``steps``, else the stored results)."""
        label = SpecimenRecord.from_attrs(attrs_of(self.h5[s.series_name(series)])).label
        curve = curve_from_steps(series, run, label, self.step_results(series, run) if steps is None else steps)
        rg = self.h5[s.series_name(series)][s.run_name(run)]
        if s.CURVE in rg:
            del rg[s.CURVE]
        g = rg.create_group(s.CURVE)
        for name, values in curve.columns().items():
            g.create_dataset(name, data=values)
        g.attrs[s.COMPLETE] = True
        rg.attrs[s.COMPLETE] = True
        rg.attrs["finished_utc"] = utc_now()
        self.h5.flush()
        return curve

    def curves(self) -> list[RepetitionCurve]:
        """Every stored repetition curve, in series and run order (the whole campaign, resumed or not)."""
        return [] if self.h5 is None else curves_of(self.h5)

    def completed_steps(self) -> list[StepStamp]:
        """Every completed step with its first impact's time (what the ETA needs)."""
        return [StepStamp(s.number(st.parent.parent), s.number(st.parent), s.number(st),
                          first_impact_s(impact_info(ig) for ig in complete_impacts(st)))
                for st in s.all_steps(self.h5) if st.attrs.get(s.COMPLETE)]

    @guarded
    def append_log(self, entry: LogEntry) -> None:
        """Append one entry to the run log (``/log``) and flush; earlier entries are never rewritten."""
        append_entry(self.h5, entry)

    def log(self) -> list[LogEntry]:
        return read_entries(self.h5)

    def set_status(self, status: str, message: str = "") -> None:
        """Record how the run ended; after a failed write it is tried once more on the reopened file, and if
        there is still no room the file keeps its last flushed status (``--resume`` and ``process`` read it)."""
        for _ in range(2):
            if self.h5 is None or self.h5.mode != "r+":
                return
            try:
                with self._writing():
                    self.h5.attrs["status"] = status
                    self.h5.attrs["status_message"] = message
                    self.h5.attrs["status_utc"] = utc_now()
                    self.h5.flush()
                return
            except DiskFull:
                continue

    def close(self) -> None:
        if self.h5 is None or not self.h5.id.valid:
            clear_writer(self.path)
            return
        try:
            self.h5.flush()
            trim(self.h5)
            self.h5.close()
        except (OSError, RuntimeError):
            discard(self.h5)  # never a half-written flush: the file stays as of its last good one
        clear_writer(self.path)

    def __enter__(self) -> CampaignWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
