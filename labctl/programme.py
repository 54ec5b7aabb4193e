"""A test programme on the simulated rig: many campaigns (one per specimen, or the paper's 18 roller/rail pairs)
spread over worker processes or a Dask cluster, one campaign file each.

A campaign is one task that runs the whole protocol on its own twin (seeded, so where it runs changes nothing)
and returns its repetition curves: the results are those of running the campaigns one after another in this
process (``workers=0``). A task never raises; what goes wrong with one campaign is that campaign's outcome.
The cluster is the archive's (``labctl.archive.runner.dask_client``): a local one of N processes, or an existing
scheduler whose workers can reach the output paths.
"""

from __future__ import annotations

import math
import os
import socket
import time
import tomllib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from labctl.errors import InputError, LabctlError
from labctl.storage.records import RepetitionCurve

PAPER_PROTOCOL = "roller_stiffness"
PAPER_TYPES = tuple(range(1, 10))  # the paper's roller types 1-9 (Table 1)
PAPER_RAILS_RA_M = (0.2e-6, 0.03e-6)  # its ground and mirror-polished rails


@dataclass(frozen=True)
class CampaignJob:
    """One campaign of a programme: its protocol (TOML text, stored in the file), the file it writes, the
    simulated rig's seed, world and rig file; ``keep_file=False`` deletes the file once its curves are in hand."""

    name: str
    protocol_text: str
    out: str
    seed: int | None = None
    world: str | None = None
    rig: str | None = None
    keep_file: bool = True


@dataclass(frozen=True)
class CampaignDone:
    """How one campaign of a programme ended: status as ``run_campaign`` reports it (or ``failed`` with the error),
    its finished repetition curves, wall and CPU seconds and the worker (host:pid) that ran it."""

    name: str
    path: str
    status: str
    message: str
    curves: tuple[RepetitionCurve, ...]
    seconds: float
    cpu_seconds: float
    worker: str

    @property
    def ok(self) -> bool:
        return self.status == "complete"

    def summary(self) -> dict[str, Any]:
        """The outcome without the curves' arrays (for ``--json``)."""
        return {"name": self.name, "path": self.path, "status": self.status, "message": self.message,
                "repetitions": len(self.curves), "identified_steps": sum(len(c.step) for c in self.curves),
                "seconds": self.seconds, "cpu_seconds": self.cpu_seconds, "worker": self.worker}


def run_job(job: CampaignJob) -> CampaignDone:
    """Run one campaign on the simulated rig; every failure is returned as the campaign's outcome, never raised."""
    from labctl.campaign import run_campaign
    from labctl.protocol.parse import parse_protocol

    t0, c0, where = time.perf_counter(), time.process_time(), f"{socket.gethostname()}:{os.getpid()}"
    try:
        protocol = parse_protocol(job.protocol_text, f"{job.name}.toml")
        outcome = run_campaign(protocol, out=job.out, backend="sim", seed=job.seed, world=job.world, rig=job.rig)
        status, message, curves = outcome.status, outcome.message, tuple(outcome.curves)
    except Exception as exc:  # noqa: BLE001 — one campaign's failure must not stop the others
        status, message, curves = "failed", " ".join(f"{job.name}: {type(exc).__name__}: {exc}".split()), ()
    if not job.keep_file:
        Path(job.out).unlink(missing_ok=True)
    return CampaignDone(job.name, job.out, status, message, curves, time.perf_counter() - t0,
                        time.process_time() - c0, where)


def run_programme(jobs: Sequence[CampaignJob], *, workers: int | None = None, scheduler: str | None = None,
                  progress: TextIO | None = None, task: Callable[[CampaignJob], CampaignDone] = run_job
                  ) -> list[CampaignDone]:
    """Run ``jobs``: one after another here when ``workers == 0`` and no scheduler, else on a Dask cluster (a local
    one of ``workers`` processes, default one per CPU, or ``scheduler``). Outcomes come back in the order of
    ``jobs``; the largest campaigns are started first so that none is left running alone at the end."""
    check_jobs(jobs)
    bar = _progress(len(jobs), progress)
    try:
        if workers == 0 and not scheduler:
            out = []
            for job in jobs:
                out.append(task(job))
                bar.update(1)
            return out
        return _on_cluster(jobs, workers, scheduler, task, bar)
    finally:
        bar.close()


def _on_cluster(jobs: Sequence[CampaignJob], workers: int | None, scheduler: str | None,
                task: Callable[[CampaignJob], CampaignDone], bar: Any) -> list[CampaignDone]:
    from distributed import as_completed

    from labctl.archive.runner import dask_client

    costs = [expected_impacts(job) for job in jobs]
    done: dict[int, CampaignDone] = {}
    with dask_client(workers if workers is not None else os.cpu_count(), scheduler) as client:
        futures = {client.submit(task, job, pure=False, priority=cost): i
                   for i, (job, cost) in enumerate(zip(jobs, costs, strict=True))}
        for fut in as_completed(list(futures)):
            i = futures[fut]
            try:
                done[i] = fut.result()
            except Exception as exc:  # noqa: BLE001 — a worker lost, or the task cannot run there
                done[i] = CampaignDone(jobs[i].name, jobs[i].out, "failed", f"{jobs[i].name}: {type(exc).__name__}: "
                                       f"{exc}", (), 0.0, 0.0, "")
            bar.update(1)
    return [done[i] for i in range(len(jobs))]


def check_jobs(jobs: Sequence[CampaignJob]) -> None:
    """Refuse, before anything runs, a programme whose campaigns would write the same file or overwrite one."""
    seen: set[str] = set()
    for job in jobs:
        path = str(Path(job.out).resolve())
        if path in seen:
            raise InputError(f"{job.out}: two campaigns of the programme would write this file")
        if Path(job.out).exists():
            raise InputError(f"{job.out}: already exists; a programme never overwrites a campaign file "
                             "(choose another --out)")
        seen.add(path)


def expected_impacts(job: CampaignJob) -> int:
    """Impacts the campaign will take if nothing is re-hit (steps × impacts × repetitions per specimen): the
    order in which a cluster starts campaigns. 0 if the protocol cannot be read (it then fails quickly)."""
    from labctl.physics.rig_config import load_rig
    from labctl.protocol.parse import parse_protocol

    try:
        proto, rig = parse_protocol(job.protocol_text, job.name), load_rig(job.rig)
    except (LabctlError, ValueError, OSError):
        return 0
    total = 0
    for spec in proto.specimens:
        per_step = spec.knob_step_deg * rig.load_per_knob_degree_n
        steps = math.floor((spec.max_load_n - rig.preload_per_roller_n) / per_step + 1e-9) + 1
        total += min(steps, proto.loading.max_steps) * proto.acquisition.impacts_per_step
    return total * proto.repetitions.count


def _progress(total: int, stream: TextIO | None) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, file=stream, unit="campaign", desc="programme", disable=stream is None,
                dynamic_ncols=True, leave=True)


# --- programmes ------------------------------------------------------------------------------------------
def paper_protocol_text(type_id: int, rail_ra_m: float, base: str | None = None) -> str:
    """The paper's §2.3 protocol (shipped ``roller_stiffness``) for one roller type on one rail finish."""
    from labctl.protocol.parse import resolve_protocol_path

    text = base if base is not None else resolve_protocol_path(PAPER_PROTOCOL).read_text(encoding="utf-8")
    ra = f"{rail_ra_m * 1e6:g}"
    out = text.replace("roller_type = 1\n", f"roller_type = {type_id}\n").replace("rail_ra_um = 0.2\n",
                                                                                  f"rail_ra_um = {ra}\n")
    if f"roller_type = {type_id}\n" not in out or f"rail_ra_um = {ra}\n" not in out:
        raise InputError(f"{PAPER_PROTOCOL}: expected 'roller_type = 1' and 'rail_ra_um = 0.2' lines to set the "
                         "paper's roller types and rails")
    return out.replace("roller type 1 on Ra 0.2 µm", f"roller type {type_id} on Ra {ra} µm")


def paper_programme(out_dir: str | Path, *, seed: int = 1, world: str | None = None, keep_files: bool = True
                    ) -> list[CampaignJob]:
    """The paper's programme: roller types 1-9 on Ra 0.2 and 0.03 µm rails, 18 campaigns; campaign i (type 1 on
    Ra 0.2 µm first) runs with seed ``seed + i``."""
    out, jobs = Path(out_dir), []
    for type_id in PAPER_TYPES:
        for ra in PAPER_RAILS_RA_M:
            name = f"paper_type{type_id}_ra{ra * 1e6:g}"
            jobs.append(CampaignJob(name, paper_protocol_text(type_id, ra), str(out / f"{name}.h5"),
                                    seed + len(jobs), world, None, keep_files))
    return jobs


def specimen_jobs(protocol_path: str | Path, out_dir: str | Path, *, first_seed: int | None = None,
                  world: str | None = None, rig: str | None = None) -> list[CampaignJob]:
    """One campaign per specimen of a protocol file: its own protocol text (the specimen's table and every other
    table of the file), file ``<stem>.h5`` (one specimen) or ``<stem>_<n>.h5``; seeds ``first_seed``, +1, ..."""
    from labctl.protocol.parse import parse_protocol, resolve_protocol_path

    path = resolve_protocol_path(protocol_path)
    text = path.read_text(encoding="utf-8")
    parse_protocol(text, str(protocol_path))  # every error named against the file the user gave
    doc = tomllib.loads(text)
    specimens = doc.pop("specimens", None)
    if specimens is None:
        texts = [text]
    else:
        texts = [f"# {path.name}, specimen {i + 1} of {len(specimens)} (labctl programme)\n"
                 + dump_toml({**doc, "specimen": spec}) for i, spec in enumerate(specimens)]
    stem, out = path.stem, Path(out_dir)
    return [CampaignJob(stem if len(texts) == 1 else f"{stem}_{i + 1}", t,
                        str(out / (f"{stem}.h5" if len(texts) == 1 else f"{stem}_{i + 1}.h5")),
                        None if first_seed is None else first_seed + i, world, rig) for i, t in enumerate(texts)]


def dump_toml(doc: Mapping[str, Any]) -> str:
    """TOML text of a protocol document: top-level tables of scalars and arrays of scalars, and arrays of tables."""
    lines: list[str] = []
    for key, table in doc.items():
        rows = table if isinstance(table, list) else [table]
        for row in rows:
            if not isinstance(row, Mapping):
                raise InputError(f"protocol key {key!r}: expected a table, got {row!r}")
            lines.append(f"[[{key}]]" if isinstance(table, list) else f"[{key}]")
            lines += [f"{k} = {_toml_value(v)}" for k, v in row.items()]
            lines.append("")
    return "\n".join(lines)


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value) if math.isfinite(value) else ("nan" if value != value else ("inf" if value > 0 else "-inf"))
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise InputError(f"protocol value {value!r}: nested tables are not supported in a programme")
