"""Export a campaign's time records, FRFs and coherences as UFF58 (ASCII 58 or binary 58b), one set at a time.

Each impact is one load case (numbered from 1 through the file); its force record sits at the hammer's node
and every accelerometer channel at its node and direction (docs/contracts.md). A step's H1 FRFs (function type 4,
acceleration over force) and coherences (type 6) come before its impacts, so readers that judge a file by its
first data set (sdypy-EMA) see accelerance FRFs. Sets are written one by one — pyuff's
list mode writes 58b files it cannot read back — into a temporary file renamed at the end, so a failed
export never leaves half a file under the requested name. An optional manifest CSV maps the load cases back
to loads and repetitions for ``labctl import``.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from labctl import __version__
from labctl.errors import InputError
from labctl.storage import CampaignReader
from labctl.storage.outputs import atomic_output, check_outputs
from labctl.storage.specimen import SpecimenRecord
from labctl.uff import mapping as m
from labctl.uff.manifest import MANIFEST_COLUMNS, format_load_cases

ASCII_LIMIT_BYTES = 100e6  # larger selections are written as binary 58b unless ASCII is asked for
ASCII_BYTES_PER_VALUE = 20.25  # E20.12, four values a line


@dataclass(frozen=True)
class Selection:
    """Which steps and records to export (None: all)."""

    series: int | None = None
    run: int | None = None
    step: int | None = None
    all_impacts: bool = False  # also the rejected impacts (their id4 line says why)
    time: bool = True
    frf: bool = True


@dataclass
class ExportSummary:
    out: str
    binary: bool
    steps: int = 0
    impacts: int = 0
    time_records: int = 0
    frfs: int = 0
    coherences: int = 0
    manifest: str | None = None
    manifest_rows: list[dict[str, Any]] = field(default_factory=list)

    @property
    def sets(self) -> int:
        return self.time_records + self.frfs + self.coherences


def _dataset(func_type: int, node: int, direction: int, data: np.ndarray, x0: float, dx: float, *,
             load_case: int, ids: tuple[str, str, str, str], ordinate: int, units: str, binary: bool,
             nodes: m.NodeMap, abscissa: int, denominator: int = 0) -> dict[str, Any]:
    n = len(data)
    return {
        "type": 58, "binary": int(binary), "func_type": func_type, "load_case_id": load_case,
        "rsp_ent_name": "labctl", "rsp_node": node, "rsp_dir": direction,
        "ref_ent_name": "labctl", "ref_node": nodes.hammer, "ref_dir": m.HAMMER_DIR,
        "id1": ids[0][:80], "id2": ids[1][:80], "id3": ids[2][:80], "id4": ids[3][:80],
        "id5": f"labctl {__version__}",
        "abscissa_spacing": 1, "abscissa_min": x0, "abscissa_inc": dx, "x": x0 + dx * np.arange(n),
        "data": data, "num_pts": n,
        "abscissa_spec_data_type": abscissa,
        "abscissa_axis_lab": "Time" if abscissa == m.ABSCISSA_TIME else "Frequency",
        "abscissa_axis_units_lab": "s" if abscissa == m.ABSCISSA_TIME else "Hz",
        "ordinate_spec_data_type": ordinate, "ordinate_axis_units_lab": units,
        "ordinate_axis_lab": {m.ORDINATE_FORCE: "Force", m.ORDINATE_ACCELERATION: "Acceleration"}.get(ordinate,
                                                                                                    "Coherence"),
        "orddenom_spec_data_type": denominator, "orddenom_axis_units_lab": "N" if denominator else "NONE",
        "orddenom_axis_lab": "Force" if denominator else "NONE",
    }


class _Out:
    """A UFF file built one data set at a time: pyuff writes each set to a scratch file that is appended.

    pyuff re-reads the whole file after every set it adds, which makes writing into one growing file
    quadratic in its size; the scratch file keeps each write as cheap as the set itself.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.scratch = path.with_name(path.name + ".set")
        self.fh = path.open("wb")

    def write(self, dset: dict[str, Any]) -> None:
        import pyuff

        self.scratch.unlink(missing_ok=True)  # 'add', not 'overwrite': pyuff's overwrite truncates 58b data
        try:
            pyuff.UFF(str(self.scratch)).write_sets(dset, mode="add")
        except Exception as exc:  # pyuff raises bare Exception
            raise InputError(f"{self.path}: cannot write UFF data set ({exc})") from None
        self.fh.write(self.scratch.read_bytes())

    def close(self) -> None:
        self.fh.close()
        self.scratch.unlink(missing_ok=True)


def _steps(reader: CampaignReader, sel: Selection) -> Iterator[tuple[int, int, Any]]:
    for series in reader.series_indices():
        if sel.series not in (None, series):
            continue
        for run in reader.runs(series):
            if sel.run not in (None, run.run):
                continue
            for step in run.steps:
                if sel.step in (None, step.step):
                    yield series, run.run, step


def ascii_size_bytes(reader: CampaignReader, steps: list[tuple[int, int, Any]], sel: Selection) -> float:
    """About how large the selected time records would be as ASCII UFF58 (the FRFs are small beside them)."""
    if not sel.time:
        return 0.0
    counts = [(series, run, step, sum(1 for i in step.impacts if sel.all_impacts or i.accepted))
              for series, run, step in steps]
    sized = next(((s, r, st) for s, r, st, n in counts if n), None)
    if sized is None:
        return 0.0
    data = reader.impact_arrays(sized[0], sized[1], sized[2].step)
    values = data.force_n.shape[1] * (1 + len(data.channels))
    return sum(n for *_, n in counts) * values * ASCII_BYTES_PER_VALUE


def export_campaign(path: str | Path, out: str | Path, *, selection: Selection = Selection(),
                    binary: bool | None = None,
                    nodes: m.NodeMap = m.DEFAULT_NODES, manifest: str | Path | None = None,
                    progress: Callable[[int, int], None] | None = None) -> ExportSummary:
    """Write the selected steps of a campaign file to ``out`` as UFF58; return what was written.

    ``binary`` None chooses: binary 58b when the ASCII file would exceed ``ASCII_LIMIT_BYTES``, else ASCII 58.

    ``progress(done, total)`` is called after each written step.
    """
    out = Path(out)
    if out.is_dir():
        raise InputError(f"{out}: is a directory, expected a .uff file name")
    check_outputs([("--uff", out), ("--manifest", manifest)], [path])
    with CampaignReader(path) as reader, atomic_output(out) as tmp:
        protocol = str(reader.attrs.get("protocol_name", ""))
        steps = list(_steps(reader, selection))
        if not steps:
            wanted = ", ".join(f"{k} {v}" for k, v in (("series", selection.series), ("run", selection.run),
                                                        ("step", selection.step)) if v is not None)
            raise InputError(f"{path}: no stored step matches {wanted or 'the selection'}")
        if binary is None:
            binary = ascii_size_bytes(reader, steps, selection) > ASCII_LIMIT_BYTES
        summary = ExportSummary(str(out), binary)
        if progress is not None:
            progress(0, len(steps))
        writer = _Out(tmp)
        try:
            for series, run, step in steps:
                label = reader.specimen(series).label or f"series {series}"
                head = f"{protocol}: {label}"[:80]
                where = f"series {series} run {run} step {step.step}"
                load = f"load {step.load_n:.6g} N per roller"
                first = summary.impacts + 1
                if selection.frf:
                    _write_frf(writer, reader, series, run, step, summary, nodes, binary, (head, where, load))
                if selection.time:
                    _write_impacts(writer, reader, series, run, step.step, selection, summary, nodes, binary,
                                   (head, where, load))
                summary.steps += 1
                if progress is not None:
                    progress(summary.steps, len(steps))
                if summary.impacts >= first:
                    summary.manifest_rows.append(_manifest_row(out.name, reader.specimen(series), run, step,
                                                               list(range(first, summary.impacts + 1))))
            if summary.sets == 0:
                raise InputError(f"{path}: nothing to export for the selected steps (no stored impacts or FRFs)")
        finally:
            writer.close()
    if manifest is not None:
        summary.manifest = str(manifest)
        write_manifest(manifest, summary.manifest_rows)
    return summary


def _write_impacts(writer: _Out, reader: CampaignReader, series: int, run: int, step: int, sel: Selection,
                   summary: ExportSummary, nodes: m.NodeMap, binary: bool, ids: tuple[str, str, str]) -> None:
    data = reader.impact_arrays(series, run, step, accepted_only=not sel.all_impacts)
    if not data.attempts:
        return
    infos = {i.attempt: i for i in reader.impact_infos(series, run, step)}
    targets = [nodes.node_dir(c) for c in data.channels]
    dt = 1.0 / data.sample_rate_hz
    for i, attempt in enumerate(data.attempts):
        summary.impacts += 1
        lc = summary.impacts
        info = infos[attempt]
        verdict = "accepted" if data.accepted[i] else "rejected: " + json.dumps(list(info.reasons))
        line = (ids[0], f"{ids[1]} impact {attempt}", info.timestamp_utc,
                f"{ids[2]}; {verdict}")
        writer.write(_dataset(m.TIME_RESPONSE, nodes.hammer, m.HAMMER_DIR, data.force_n[i], 0.0, dt, load_case=lc,
                              ids=line, ordinate=m.ORDINATE_FORCE, units="N", binary=binary, nodes=nodes,
                              abscissa=m.ABSCISSA_TIME))
        for c, (node, direction) in enumerate(targets):
            writer.write(_dataset(m.TIME_RESPONSE, node, direction, data.accel_m_per_s2[i, c], 0.0, dt,
                                  load_case=lc, ids=line, ordinate=m.ORDINATE_ACCELERATION, units="m/s^2",
                                  binary=binary, nodes=nodes, abscissa=m.ABSCISSA_TIME))
        summary.time_records += 1 + len(targets)


def _write_frf(writer: _Out, reader: CampaignReader, series: int, run: int, step: Any, summary: ExportSummary,
               nodes: m.NodeMap, binary: bool, ids: tuple[str, str, str]) -> None:
    frf = reader.step_frf(series, run, step.step)
    if frf is None:
        return
    freqs, h1, coherence = frf
    channels = (list(step.result.channels) if step.result is not None else []) or list(
        reader.impact_arrays(series, run, step.step, accepted_only=True).channels)
    if len(channels) != h1.shape[0] or len(freqs) < 2:
        raise InputError(f"{reader.path}: {ids[1]}: the stored FRF has {h1.shape[0]} rows for "
                         f"{len(channels)} channels")
    f0, df = float(freqs[0]), float(freqs[1] - freqs[0])
    when = str(step.attrs.get("created_utc", ""))
    for c, name in enumerate(channels):
        node, direction = nodes.node_dir(name)
        writer.write(_dataset(m.FRF, node, direction, h1[c].astype(complex), f0, df, load_case=0,
                              ids=(ids[0], f"{ids[1]} H1 {name}", when, ids[2]),
                              ordinate=m.ORDINATE_ACCELERATION, units="m/s^2", binary=binary, nodes=nodes,
                              abscissa=m.ABSCISSA_FREQUENCY, denominator=m.ORDINATE_FORCE))
        summary.frfs += 1
        if np.isfinite(coherence[c]).all():
            writer.write(_dataset(m.COHERENCE, node, direction, coherence[c].astype(float), f0, df, load_case=0,
                                  ids=(ids[0], f"{ids[1]} coherence {name}", when, ids[2]),
                                  ordinate=m.ORDINATE_UNKNOWN, units="NONE", binary=binary, nodes=nodes,
                                  abscissa=m.ABSCISSA_FREQUENCY))
            summary.coherences += 1


def _manifest_row(file: str, specimen: SpecimenRecord, run: int, step: Any, load_cases: list[int]
                  ) -> dict[str, Any]:
    rt = specimen.roller_type
    return {"file": file, "load_cases": format_load_cases(load_cases), "load_n": f"{step.load_n:.12g}",
            "repetition": run, "step": step.step,
            "knob_angle_deg": f"{float(step.attrs.get('knob_angle_deg', float('nan'))):.12g}",
            "roller_type": "" if rt is None else int(rt),
            "rail_ra_um": f"{specimen.rail_ra_m * 1e6:.12g}"}


def write_manifest(path: str | Path, rows: list[dict[str, Any]]) -> None:
    """The manifest CSV ``labctl import`` reads: one row per load step, units in the column names."""
    with atomic_output(path) as tmp, Path(tmp).open("w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(MANIFEST_COLUMNS))
        w.writeheader()
        for row in rows:
            w.writerow({k: row.get(k, "") for k in MANIFEST_COLUMNS})
