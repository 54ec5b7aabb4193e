"""The rollback journal in process: a file caught at every write call of a flush (what a SIGKILL there leaves,
file and journal as the kernel holds them) is rolled back to the last completed flush exactly."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from labctl.errors import InputError
from labctl.storage.rollback import MAGIC, JournaledFile, RollbackFile, journal_path, recover


def _state(path: Path) -> dict[str, object]:
    """Every object's name, attributes and data (what the file holds)."""
    out: dict[str, object] = {}
    with h5py.File(path, "r") as f:
        out["/"] = dict(f.attrs)

        def visit(name: str, obj: object) -> None:
            attrs = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in obj.attrs.items()}
            data = obj[()].tolist() if isinstance(obj, h5py.Dataset) else None
            out[name] = (attrs, data)

        f.visititems(visit)
    return out


def _first_state(path: Path) -> None:
    with h5py.File(path, "w") as f:
        f.attrs["status"] = "running"
        for i in range(3):
            g = f.create_group(f"series_01/run_01/step_{i:03d}")
            g.attrs["load_n"] = 10.0 * i
            g.create_dataset("force_n", data=np.arange(5000, dtype=np.int32) * i, chunks=(1024,),
                             compression="gzip")


def _second_flush(f: h5py.File) -> None:
    """What a flush may hold: new groups and data, changed and deleted attributes, a deleted group."""
    f.attrs["status"] = "complete"
    f.attrs["status_message"] = "x" * 300
    del f["series_01/run_01/step_001"]
    g = f.create_group("series_01/run_01/step_003")
    g.attrs["load_n"] = 30.0
    g.create_dataset("force_n", data=np.arange(20000, dtype=np.int32), chunks=(1024,), compression="gzip")
    f["series_01/run_01/step_000"].attrs["complete"] = True


def test_a_file_caught_at_any_write_of_a_flush_rolls_back_to_the_last_one(tmp_path: Path,
                                                                          monkeypatch: pytest.MonkeyPatch):
    path = tmp_path / "c.h5"
    _first_state(path)
    flushed = _state(path)
    snaps: list[tuple[Path, int]] = []  # (copy, number of the last completed flush: 1 or 2)
    real, commits = RollbackFile.write, [1]

    def write(self: RollbackFile, data: bytes) -> int:  # before each write: the file as a kill here leaves it
        snap = tmp_path / f"s{len(snaps)}"
        snap.mkdir()
        shutil.copy(path, snap / "c.h5")
        if self.journal.exists():
            shutil.copy(self.journal, journal_path(snap / "c.h5"))
        snaps.append((snap / "c.h5", commits[0]))
        return real(self, data)

    monkeypatch.setattr(RollbackFile, "write", write)
    f = JournaledFile(path)
    _second_flush(f)
    f.flush()
    commits[0] = 2
    f.close()  # closing writes the superblock again: caught there, the file is the second flush's
    monkeypatch.setattr(RollbackFile, "write", real)
    states = {1: flushed, 2: _state(path)}
    assert sum(n == 1 for _, n in snaps) >= 10 and states[2]["/"]["status"] == "complete"
    broken = 0
    for snap, n in snaps:
        try:
            broken += _state(snap) != states[n]
        except Exception:  # noqa: BLE001 — what HDF5 makes of a half-flushed file
            broken += 1
        recover(snap)
        assert not journal_path(snap).exists()
        assert _state(snap) == states[n], snap  # exactly the last flush, whatever the write caught
    assert broken >= 1  # without the journal some of these files were not the flushed one


def test_a_torn_last_journal_record_is_ignored(tmp_path: Path):
    path = tmp_path / "c.h5"
    _first_state(path)
    flushed = _state(path)
    f = JournaledFile(path)
    f.attrs["status"] = "changed"
    h5py.File.flush(f)  # HDF5's flush without the commit: the journal stays, as a kill after the flush leaves it
    f.rollback.close()  # the process dies here: nothing more reaches the file
    f.close()
    journal = journal_path(path)
    data = journal.read_bytes()
    assert data.startswith(MAGIC)
    journal.write_bytes(data + b"\x01\x02\x03")  # a record cut short by the kill
    assert recover(path)
    assert _state(path) == flushed


def test_a_live_writer_keeps_its_journal_and_readers_see_it_busy(tmp_path: Path):
    path = tmp_path / "c.h5"
    _first_state(path)
    f = JournaledFile(path)
    f.attrs["status"] = "changed"
    h5py.File.flush(f)  # flushed, not committed: the journal is live
    assert journal_path(path).exists()
    assert not recover(path)  # the writer holds the lock: nothing is rolled back under it
    assert journal_path(path).exists()
    with pytest.raises(OSError, match="lock"):
        h5py.File(path, "r")
    f.flush()
    f.close()
    assert not journal_path(path).exists() and _state(path)["/"]["status"] == "changed"


def test_a_journal_that_cannot_be_applied_is_one_line(tmp_path: Path):
    path = tmp_path / "c.h5"
    _first_state(path)
    journal_path(path).write_bytes(MAGIC)
    os.chmod(path, 0o444)
    try:
        if os.access(path, os.W_OK):
            pytest.skip("running as root: every file is writable")
        with pytest.raises(InputError, match="needs write access"):
            recover(path)
    finally:
        os.chmod(path, 0o644)


def test_a_journal_larger_than_its_file_could_need_is_refused(tmp_path: Path):
    from labctl.storage import CampaignReader

    path = tmp_path / "c.h5"
    _first_state(path)
    journal_path(path).write_bytes(MAGIC + b"\0" * (3 * path.stat().st_size + 2**20))
    with pytest.raises(InputError, match="more than a rollback journal"):
        CampaignReader(path)
