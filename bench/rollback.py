"""Rollback-journal bench: ms to write one impact through the journaled file object (what `labctl run` does)
against the same writer on HDF5's own sec2 driver (no journal, not crash-safe inside a flush), and the journal's
peak size per impact, on records of the simulated rig (65 536 samples, 13 channels).

    PYTHONPATH=. python bench/rollback.py [N_IMPACTS]

Run by hand (not a test). Times are medians over the impacts, both columns in one run.
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
from pathlib import Path
from unittest import mock

import h5py

import labctl.storage.writer as writer_module
from bench.storage import records, write_v2
from labctl.backends import make_rig
from labctl.storage.rollback import RollbackFile


def main(n: int = 10) -> int:
    recs, proto = records(n)
    rig = make_rig("sim", case=proto.specimens[0].case(), seed=1)  # type: ignore[attr-defined]
    peak = [0]
    real_save = RollbackFile._save

    def save(self: RollbackFile, start: int, end: int) -> None:
        real_save(self, start, end)
        peak[0] = max(peak[0], os.path.getsize(self.journal))

    with tempfile.TemporaryDirectory() as tmp:
        with mock.patch.object(RollbackFile, "_save", save):
            journaled = write_v2(Path(tmp) / "j.h5", recs, rig, proto)
        with mock.patch.object(writer_module, "JournaledFile", lambda p: h5py.File(p, "r+")):
            plain = write_v2(Path(tmp) / "p.h5", recs, rig, proto)
    print(f"{n} impacts of {recs[0].accel_m_per_s2.shape[0] + 1} channels × {recs[0].force_n.size} samples")
    med = {}
    for name, t in (("sec2 driver, no journal   ", plain), ("rollback journal (labctl)", journaled)):
        med[name] = wall, cpu = tuple(statistics.median(x[i] for x in t) * 1e3 for i in (0, 1))
        print(f"{name}: write {wall:6.1f} ms wall, {cpu:6.1f} ms CPU per impact")
    (w0, c0), (w1, c1) = med.values()
    print(f"journal/no journal: {w1 / w0:.2f}× wall, {c1 / c0:.2f}× CPU; journal peak {peak[0] / 1024:.0f} KiB")
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    return 0


if __name__ == "__main__":
    sys.exit(main(*(int(a) for a in sys.argv[1:])))
