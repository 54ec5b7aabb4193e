"""Reprocess many campaign files: in this process, on a local Dask cluster, or on an existing scheduler.

Each file is one task that reads the raw impacts, identifies every step again and writes the results sidecar
beside the file (labctl/storage/results.py). A task never raises: whatever goes wrong with one file becomes
that file's outcome, so one corrupt file cannot stop the others. Dask is imported only here, and only when a
cluster is asked for.
"""

from __future__ import annotations

import contextlib
import logging
import os
import socket
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, TextIO

from labctl import __version__
from labctl.archive.source import Reprocessed, reprocess
from labctl.errors import InputError
from labctl.storage.results import write_results

CONNECT_TIMEOUT_S = 15.0


@dataclass(frozen=True)
class FileOutcome:
    """How reprocessing one campaign file went."""

    path: str
    ok: bool
    error: str = ""
    steps: int = 0
    identified: int = 0
    written: bool = False
    seconds: float = 0.0
    cpu_seconds: float = 0.0
    worker: str = ""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def results_document(done: Reprocessed) -> dict[str, Any]:
    """The sidecar's content: what was computed, from which file state, with which software and rig."""
    return {
        "software_version": __version__,
        "source": {"file_name": Path(done.path).name, "size_bytes": done.size_bytes, "root_sha256": done.root_sha256},
        "rig": asdict(done.rig),
        "status": done.status,
        "steps": done.steps,
        "points": [asdict(p) for p in done.points],
    }


def reprocess_file(path: str) -> FileOutcome:
    """Reprocess one campaign file and store its results beside it; failures are returned, never raised."""
    t0, c0 = time.perf_counter(), time.process_time()
    where = _where()
    try:
        done = reprocess(path)
        written = write_results(path, results_document(done))
    except Exception as exc:  # noqa: BLE001 — isolate every failure of one file from the others
        msg = str(exc) if str(path) in str(exc) else f"{path}: {type(exc).__name__}: {exc}"
        return FileOutcome(str(path), False, " ".join(msg.split()), seconds=time.perf_counter() - t0,
                           cpu_seconds=time.process_time() - c0, worker=where)
    identified = sum(1 for s in done.steps if s["result"] is not None)
    return FileOutcome(str(path), True, "", len(done.steps), identified, written, time.perf_counter() - t0,
                       time.process_time() - c0, where)


def _where() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


@contextlib.contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None) -> Iterator[Any]:
    """A ``distributed.Client``: connected to ``scheduler``, or to a new local cluster of ``workers`` processes
    with one thread each (processing is CPU-bound Python and NumPy: processes, not threads, scale)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise InputError("Dask is not installed: pip install 'dask[distributed]'") from None
    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError) as exc:
            raise InputError(f"cannot reach the Dask scheduler at {scheduler!r} ({exc})") from None
        try:
            yield client
        finally:
            client.close()
        return
    import dask

    with dask.config.set(_local_worker_config()):
        cluster = LocalCluster(n_workers=max(1, workers or 1), threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=logging.ERROR)
    client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


def dask_map(fn: Callable[[Any], Any], items: Sequence[Any], *, scheduler: str | None = None,
             workers: int | None = None) -> list[Any]:
    """``[fn(x) for x in items]`` on a Dask cluster (an existing scheduler, else a local one); the first
    failure is raised. For batch jobs whose tasks must all succeed (e.g. bench/discrepancy_eval.py)."""
    with dask_client(workers, scheduler) as client:
        return list(client.gather(client.map(fn, list(items), pure=False)))


def _local_worker_config() -> dict[str, Any]:
    """Worker settings for processing: distributed's default ``MALLOC_TRIM_THRESHOLD_`` makes every large
    NumPy array a fresh mmap (measured: twice the CPU time per campaign) and its statistical profiler adds
    more; both are off in the local cluster."""
    import dask

    environ = dask.config.get("distributed.nanny.pre-spawn-environ", default={}) or {}
    return {"distributed.nanny.pre-spawn-environ": {k: v for k, v in environ.items() if k != "MALLOC_TRIM_THRESHOLD_"},
            "distributed.worker.profile.enabled": False}


def _progress(total: int, stream: TextIO | None) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, file=stream, unit="file", desc="reprocessing", disable=stream is None,
                dynamic_ncols=True, leave=True)


def process_files(paths: Sequence[str | Path], *, workers: int | None = None, scheduler: str | None = None,
                  progress: TextIO | None = None, task: Callable[[str], FileOutcome] = reprocess_file
                  ) -> list[FileOutcome]:
    """Reprocess ``paths``: sequentially here when ``workers == 0`` and no scheduler, else with Dask.

    Outcomes come back in the order of ``paths``. ``progress``: a stream for a progress bar (None: quiet).
    """
    names = [str(p) for p in paths]
    if workers == 0 and not scheduler:
        with _Tally(names, progress) as tally:
            for name in names:
                tally.done(task(name))
        return tally.ordered()
    from distributed import as_completed

    with dask_client(workers, scheduler) as client, _Tally(names, progress) as tally:
        futures = client.map(task, names, pure=False)
        path_of = {f.key: n for f, n in zip(futures, names, strict=True)}
        for fut in as_completed(futures):
            try:
                tally.done(fut.result())
            except Exception as exc:  # noqa: BLE001 — a worker lost, or the task cannot run there
                name = path_of[fut.key]
                tally.done(FileOutcome(name, False, f"{name}: {type(exc).__name__}: {exc}"))
    return tally.ordered()


class _Tally:
    """Outcomes as they arrive, with a progress bar on a stream (failures printed above it)."""

    def __init__(self, names: list[str], stream: TextIO | None) -> None:
        self.names, self.stream = names, stream
        self.outcomes: dict[str, FileOutcome] = {}
        self.bar = _progress(len(names), stream)

    def done(self, out: FileOutcome) -> None:
        self.outcomes[out.path] = out
        if not out.ok and self.stream is not None:
            self.bar.write(f"failed: {out.error}", file=self.stream)
        self.bar.update(1)

    def ordered(self) -> list[FileOutcome]:
        return [self.outcomes[n] for n in self.names]

    def __enter__(self) -> _Tally:
        return self

    def __exit__(self, *exc: object) -> None:
        self.bar.close()
