"""The campaign writer's guard against failed writes: every writing method runs inside ``_writing``.

A write that fails (disk full, file-size limit, I/O error) is never flushed: the handle is dropped and its
rollback journal undoes what it wrote since its last flush (``labctl.storage.rollback``), the file is
reopened with partial groups removed, and ``DiskFull`` is raised so the engine stops the run as
``interrupted`` (resumable once there is room).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TypeVar

import h5py

from labctl.storage import schema as s
from labctl.storage.diskspace import RESERVE_BYTES, DiskFull, discard, is_full, reserve
from labctl.storage.reader import complete_impacts
from labctl.storage.records import ImpactInfo
from labctl.storage.rollback import JournaledFile

T = TypeVar("T")


def guarded(method: Callable[..., T]) -> Callable[..., T]:
    """A writing method: a failed write reopens the file as of its last flush and raises DiskFull."""

    @functools.wraps(method)
    def wrapper(self: WriteGuard, *args: Any, **kw: Any) -> T:
        with self._writing():
            return method(self, *args, **kw)

    return wrapper


class WriteGuard:
    """Mixin of ``CampaignWriter``: room reservation and recovery from a failed write."""

    h5: h5py.File
    path: str
    _accepted: int | None
    _infos: dict[tuple[int, int, int], list[ImpactInfo]]

    def _kept(self) -> int:
        try:
            return sum(len(complete_impacts(st)) for st in s.all_steps(self.h5))
        except Exception:  # noqa: BLE001 — only for the message
            return 0

    def ensure_room(self, need_bytes: int) -> None:
        """Reserve room for ``need_bytes`` plus ``RESERVE_BYTES`` (what ends a step and the run) or raise
        DiskFull with nothing written."""
        try:
            reserve(self.h5, need_bytes + RESERVE_BYTES)
        except DiskFull as exc:
            raise DiskFull(f"{self.path}: {exc}: {self._kept()} impacts kept; free space and --resume") from None

    @contextmanager
    def _writing(self) -> Iterator[None]:
        """Run a write; when it fails, reopen the file as of its last flush and raise DiskFull."""
        try:
            yield
        except DiskFull:
            raise
        except (OSError, RuntimeError, KeyError, ValueError) as exc:
            if not isinstance(exc, OSError | RuntimeError) and self.h5 is not None and self.h5.id.valid:
                raise  # a programming error on a healthy file, not a failed write
            what = "disk full" if is_full(exc) else f"write failed ({' '.join(str(exc).split())[:200]})"
            self._recover()
            raise DiskFull(f"{self.path}: {what}: {self._kept()} impacts kept; free space and --resume") from None

    def _recover(self) -> None:
        """Drop the failed handle unflushed, reopen the file as of its last flush, remove partial groups."""
        discard(self.h5)
        self._accepted = None
        self._infos.clear()
        try:
            self.h5 = JournaledFile(self.path)
            self._drop_incomplete()
            self.h5.flush()
        except Exception:  # noqa: BLE001 — still no room: keep the file as it is on disk, read-only
            discard(self.h5)
            try:
                self.h5 = h5py.File(self.path, "r")
            except OSError:
                self.h5 = None  # type: ignore[assignment]

    def _drop_incomplete(self) -> None:
        """Remove every group whose write did not finish (no ``complete``): impacts, step results, curves."""
        for run in list(s.all_runs(self.h5)):
            for step in s.children(run, "step_"):
                for group in [*s.children(step, "impact_"), step.get(s.RESULT)]:
                    if group is not None and not group.attrs.get(s.COMPLETE, False):
                        del self.h5[group.name]
            curve = run.get(s.CURVE)
            if curve is not None and not curve.attrs.get(s.COMPLETE, False):
                del self.h5[curve.name]
