"""``labctl import``: UFF58 time data from another acquisition system plus a manifest → a campaign file.

Each manifest row is one load step: its impacts (load cases of a UFF file) are checked, stored and
identified like the engine's, and each repetition gets its stiffness curve, so ``labctl process``,
``report`` and ``export`` read the result like any campaign. The whole input is checked before anything is
written; a failure while writing removes the partial file.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from drivers.interfaces import Record
from labctl.engine.sequencer import specimen_record
from labctl.errors import InputError
from labctl.physics.rig_config import RigConfig, load_rig
from labctl.processing import CheckConfig
from labctl.protocol import SpecimenSpec
from labctl.recording import check_record, process_step
from labctl.storage import CampaignWriter, StepResult
from labctl.uff import mapping as m
from labctl.uff.manifest import ManifestRow, read_manifest
from labctl.uff.reader import ImpactPlan, UffFile, UffImpacts, plan_uff_impacts

DEFAULT_RAIL_RA_M = 0.2e-6

@dataclass(frozen=True)
class ImportOptions:
    """Specimen defaults for rows that do not name them, and how to read the files."""

    roller_type: int | None = None
    rail_ra_m: float | None = None
    rail_material: str = "1.3505"
    rig: str | Path | None = None
    nodes: m.NodeMap = m.DEFAULT_NODES
    sample_rate_hz: float | None = None  # overrides the rate recovered from the files' sample interval
    checks: CheckConfig = CheckConfig()


@dataclass
class PlannedStep:
    row: ManifestRow
    file: Path
    series: int
    run: int
    step: int


@dataclass
class ImportSummary:
    out: str
    series: list[dict[str, Any]] = field(default_factory=list)
    steps: list[dict[str, Any]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def _resolve(rows: list[ManifestRow], files: list[Path], manifest: Path) -> list[Path]:
    """The UFF file of every row; every file given on the command line must be used."""
    out = []
    for row in rows:
        if row.file is None:
            if len(files) != 1:
                raise InputError(f"{manifest}: row {row.line}, column file: empty; name the UFF file when "
                                 f"importing {'several files' if files else 'from a manifest alone'}")
            out.append(files[0])
            continue
        if not files:
            out.append(manifest.parent / row.file)
            continue
        match = [f for f in files if f.name == Path(row.file).name or f == Path(row.file)]
        if not match:
            raise InputError(f"{manifest}: row {row.line}, column file: {row.file!r} is none of the files given "
                             f"({', '.join(str(f) for f in files)})")
        out.append(match[0])
    unused = [str(f) for f in files if f not in out]
    if unused:
        raise InputError(f"{manifest}: no row uses {', '.join(unused)}")
    return out


def plan_import(rows: list[ManifestRow], files: list[Path], manifest: Path, opts: ImportOptions
                ) -> tuple[list[PlannedStep], list[SpecimenSpec]]:
    """Series, runs and step numbers for every manifest row."""
    paths = _resolve(rows, files, manifest)
    series: dict[tuple[int, float], int] = {}
    specs: list[SpecimenSpec] = []
    plan: list[PlannedStep] = []
    used: dict[tuple[int, int], set[int]] = defaultdict(set)
    for row, path in zip(rows, paths, strict=True):
        rt = row.roller_type if row.roller_type is not None else opts.roller_type
        if rt is None:
            raise InputError(f"{manifest}: row {row.line}: no roller type (give --roller-type or a roller_type "
                             "column)")
        ra = row.rail_ra_m if row.rail_ra_m is not None else (opts.rail_ra_m if opts.rail_ra_m is not None
                                                              else DEFAULT_RAIL_RA_M)
        key = (rt, round(ra, 12))
        if key not in series:
            series[key] = len(series) + 1
            try:
                specs.append(_spec(rt, ra, opts.rail_material))
            except InputError as exc:
                source = "column roller_type" if row.roller_type is not None else "--roller-type"
                raise InputError(f"{manifest}: row {row.line}, {source}: {exc}") from None
        s = series[key]
        number = row.step if row.step is not None else len(used[(s, row.repetition)]) + 1
        if number in used[(s, row.repetition)]:
            raise InputError(f"{manifest}: row {row.line}, column step: step {number} of repetition "
                             f"{row.repetition} (roller type {rt}) appears twice")
        used[(s, row.repetition)].add(number)
        plan.append(PlannedStep(row, path, s, row.repetition, number))
    _check_cases(plan, manifest)
    specs = [replace(spec, max_load_n=max(p.row.load_n for p in plan if p.series == i))
             for i, spec in enumerate(specs, start=1)]
    return sorted(plan, key=lambda p: (p.series, p.run, p.step)), specs


def _check_cases(plan: list[PlannedStep], manifest: Path) -> None:
    """No impact may belong to two steps."""
    by_file: dict[Path, list[PlannedStep]] = defaultdict(list)
    for p in plan:
        by_file[p.file].append(p)
    for file, steps in by_file.items():
        whole = [p for p in steps if p.row.load_cases is None]
        if whole and len(steps) > 1:
            other = next(p for p in steps if p is not whole[0])
            raise InputError(f"{manifest}: row {whole[0].row.line} takes every impact of {file.name} but row "
                             f"{other.row.line} uses the same file; give each row its load_cases")
        seen: dict[int, int] = {}
        for p in steps:
            for case in p.row.load_cases or ():
                if case in seen:
                    raise InputError(f"{manifest}: row {p.row.line}: load case {case} of {file.name} is also "
                                     f"used by row {seen[case]}")
                seen[case] = p.row.line


def _spec(roller_type: int, rail_ra_m: float, rail_material: str) -> SpecimenSpec:
    spec = SpecimenSpec(kind="roller", label=f"roller type {roller_type}", roller_type=roller_type,
                        ball_diameter_m=None, ball_material=rail_material, rail_material=rail_material,
                        rail_ra_m=rail_ra_m, max_load_n=math.nan, knob_step_deg=math.nan)
    spec.case()  # an unknown roller type or material fails here, before anything is written
    return spec


def _timestamp(ids: tuple[str, ...]) -> float:
    """The impact's time from the record's id3 line (ISO 8601 or UFF 'DD-Mon-YY HH:MM:SS'), else now."""
    text = ids[2] if len(ids) > 2 else ""
    for parse in (datetime.fromisoformat, lambda t: datetime.strptime(t, "%d-%b-%y %H:%M:%S")):
        try:
            stamp = parse(text)
        except ValueError:
            continue
        return (stamp if stamp.tzinfo else stamp.replace(tzinfo=UTC)).timestamp()
    return datetime.now(UTC).timestamp()


def import_uff(files: list[str | Path], manifest: str | Path, out: str | Path, opts: ImportOptions = ImportOptions(),
               progress: Callable[[int, int], None] | None = None) -> ImportSummary:
    """Build a campaign file at ``out`` from UFF58 files and a manifest; return per-step results.

    ``progress(done, total)`` is called after each stored step (total: the manifest's steps).
    """
    manifest, out = Path(manifest), Path(out)
    if out.exists():
        raise InputError(f"{out}: already exists; choose another --out")
    rows = read_manifest(manifest)
    plan, specs = plan_import(rows, [Path(f) for f in files], manifest, opts)
    rig = load_rig(opts.rig)
    if progress is not None:
        progress(0, len(plan))
    opened = {f: UffFile(f) for f in dict.fromkeys(p.file for p in plan)}  # each file scanned once
    impacts: dict[int, ImpactPlan] = {}
    for p in plan:
        try:
            impacts[id(p)] = plan_uff_impacts(opened[p.file], opts.nodes, p.row.load_cases)
        except InputError as exc:
            raise InputError(f"{manifest}: row {p.row.line}: {exc}") from None
    summary = ImportSummary(str(out))
    for p in plan:
        summary.notes.extend(n for n in impacts[id(p)].notes if n not in summary.notes)
    writer = CampaignWriter.create(
        out, protocol_name="uff import", backend="import", seed=None,
        config_files={"rig.toml": Path(rig.source).read_text(encoding="utf-8") if rig.source else "",
                      "manifest.csv": manifest.read_text(encoding="utf-8-sig")},
        description={"source": "UFF58 import", "files": sorted({str(f) for f in opened}),
                     "manifest": str(manifest), "nodes": opts.nodes.describe()})
    try:
        with writer:
            for i, spec in enumerate(specs, start=1):
                writer.series(i, specimen_record(spec))
                writer.mark_mounted(i)
                summary.series.append({"series": i, "label": spec.label, "roller_type": spec.roller_type,
                                       "rail_ra_m": spec.rail_ra_m})
            runs: dict[tuple[int, int], list[tuple[PlannedStep, StepResult]]] = defaultdict(list)
            for p in plan:
                writer.run(p.series, p.run)
                data = impacts[id(p)].read()
                ident = _store_step(writer, p, data, rig, opts)
                runs[(p.series, p.run)].append((p, ident))
                summary.steps.append(_step_summary(p, data, ident))
                if progress is not None:
                    progress(len(summary.steps), len(plan))
            for s, r in runs:
                writer.store_curve(s, r)
            writer.set_status("complete", f"imported from {len(opened)} UFF file(s)")
    except BaseException:
        out.unlink(missing_ok=True)
        raise
    return summary


def _store_step(writer: CampaignWriter, p: PlannedStep, imp: UffImpacts, rig: RigConfig, opts: ImportOptions
                ) -> StepResult:
    """Store a step's impacts with their checks, then its result through the one step pipeline."""
    fs = opts.sample_rate_hz or imp.fs_hz
    load = p.row.load_n
    writer.step(p.series, p.run, p.step, {"knob_angle_deg": p.row.knob_angle_deg, "load_n": load,
                                          "load_total_n": load * rig.roller_count, "load_stable": True,
                                          "source_file": str(p.file), "load_cases": list(imp.load_cases)})
    stored = [writer.write_impact(p.series, p.run, p.step,
                                  check_record(Record(fs, imp.force_n[i], imp.accel_m_per_s2[i], tuple(imp.channels), 0,
                                                      _timestamp(imp.ids[i])), i + 1, opts.checks))
              for i in range(len(imp.load_cases))]
    result = process_step(stored, rig, opts.checks)
    writer.write_step_result(p.series, p.run, p.step, result)
    return result


def _step_summary(p: PlannedStep, imp: UffImpacts, ident: StepResult) -> dict[str, Any]:
    out: dict[str, Any] = {"series": p.series, "run": p.run, "step": p.step, "load_n": p.row.load_n,
                           "file": str(p.file), "load_cases": list(imp.load_cases), "impacts": len(imp.load_cases)}
    if not ident.identified:
        out["error"] = ident.error
        return out
    out.update({"accepted": len(ident.used_attempts), "bounce_hz": ident.bounce_hz,
                "roller_stiffness_n_per_m": ident.roller_stiffness_n_per_m,
                "coherence_at_bounce": ident.coherence_at_bounce})
    return out
