"""A writer killed at any write, including inside HDF5's own flush, loses no flushed impact.

Each campaign is killed by SIGKILL at a chosen write call of its file (the Nth call HDF5 makes to the
writer's file object: a named, deterministic kill point, not a timing), then resumed: the file opens, every
impact readable after the kill is in the finished campaign bit for bit, and the steps and loads are those of
an uninterrupted run of the same seed. Without the rollback journal most kill points inside a flush leave a
file HDF5 cannot open ("addr overflow", "len not positive after adjustment for EOA").
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
from pathlib import Path

import numpy as np
import pytest

from labctl.storage import CampaignReader
from labctl.storage.rollback import RollbackFile, journal_path
from tests.test_campaign_safety import SMALL

pytestmark = pytest.mark.waits  # on other processes or real time (tests/conftest.py)

FORK = multiprocessing.get_context("fork")


@pytest.fixture(scope="module", autouse=True)
def _imported() -> None:
    """What `labctl run` imports, imported once here so each forked child starts at once."""
    import labctl.campaign  # noqa: F401
    import labctl.cli  # noqa: F401
    import labctl.cli.run  # noqa: F401


@pytest.fixture(scope="module")
def protocol(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("proto") / "small.toml"
    path.write_text(SMALL, encoding="utf-8")
    return path


def _killing_child(argv: list[str], kill_at: int | None, count_file: str, log: str) -> None:
    """`labctl ARGV` in a forked child whose file writes are counted; SIGKILL at write number ``kill_at``."""
    fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    sys.stdout = sys.stderr = os.fdopen(os.dup(fd), "w", buffering=1)
    calls = [0]
    real_write, real_truncate = RollbackFile.write, RollbackFile.truncate

    def tick() -> None:
        calls[0] += 1
        if kill_at is not None and calls[0] >= kill_at:
            os.kill(os.getpid(), signal.SIGKILL)

    def write(self, data):  # type: ignore[no-untyped-def]
        tick()
        return real_write(self, data)

    def truncate(self, size=None):  # type: ignore[no-untyped-def]
        tick()
        return real_truncate(self, size)

    RollbackFile.write, RollbackFile.truncate = write, truncate  # type: ignore[method-assign]
    from labctl.cli import main

    code = main(argv)
    Path(count_file).write_text(str(calls[0]))
    sys.stdout.flush()
    os._exit(code)


def _run(argv: list[str], kill_at: int | None, tmp: Path) -> tuple[int | None, int]:
    count, log = tmp / "count.txt", tmp / "log.txt"
    count.unlink(missing_ok=True)
    proc = FORK.Process(target=_killing_child, args=(argv, kill_at, str(count), str(log)))
    proc.start()
    proc.join(120)
    return proc.exitcode, int(count.read_text()) if count.exists() else -1


def _impacts(path: Path) -> dict[tuple[int, int], tuple[str, np.ndarray, np.ndarray]]:
    with CampaignReader(path) as r:  # rolls back what the killed writer left unflushed
        if not r.series_indices():
            return {}
        return {(s.step, i.info.attempt): (i.info.timestamp_utc, i.force_n, i.accel_m_per_s2)
                for run in r.runs(1) for s in run.steps for i in r.impacts(1, run.run, s.step)}


def _plan(path: Path) -> list[tuple[int, float, float]]:
    with CampaignReader(path) as r:
        return [(s.step, s.knob_angle_deg, s.load_n) for run in r.runs(1) for s in run.steps]


def _kept(before: dict, after: dict) -> list:
    """Impacts readable after a kill that the finished campaign lacks or holds differently."""
    return [key for key, (stamp, force, accel) in before.items()
            if key not in after or after[key][0] != stamp
            or not (np.array_equal(after[key][1], force) and np.array_equal(after[key][2], accel))]


def test_twenty_kills_at_any_write_keep_every_flushed_impact_and_the_step_plan(protocol: Path, tmp_path: Path):
    """12 campaigns, each killed at a seeded write call of its run (from the new file's first write to the
    last step), 8 of them killed again while resuming (inside the roll-back and the removal of the partial
    impact too), then resumed to the end: at least 20 SIGKILLs in all."""
    reference = tmp_path / "ref.h5"
    argv = ["run", str(protocol), "--seed", "11", "--quiet", "--out"]
    code, total = _run([*argv, str(reference)], None, tmp_path)
    assert code == 0 and total > 40, total
    ref_plan = _plan(reference)
    rng = np.random.default_rng(27)
    points = [1, 3, *sorted(rng.integers(4, total, 10).tolist())]  # the first writes: creation, first impact
    lost, kills, rolled_back = [], 0, 0
    for k, n in enumerate(points):
        out = tmp_path / f"k{k}.h5"
        seen: dict = {}
        for kill_at in (n, int(rng.integers(1, 40)) if k % 3 else None, None):
            again = [*argv, str(out), "--resume"] if out.exists() else [*argv, str(out)]
            code, writes = _run(again, kill_at, tmp_path)
            if kill_at is None:
                assert code == 0, (n, (tmp_path / "log.txt").read_text())
                break
            if code == 0:  # the run finished before its kill point
                continue
            assert code == -signal.SIGKILL, (n, code)
            kills += 1
            if out.exists():
                rolled_back += journal_path(out).exists()
                if k % 2:  # a reader rolls the file back (else the resume does): what it sees must survive
                    seen.update(_impacts(out))
        after = _impacts(out)
        lost += [(n, key) for key in _kept(seen, after)]
        plan = _plan(out)
        assert [(s, a) for s, a, _ in plan] == [(s, a) for s, a, _ in ref_plan], (n, plan, ref_plan)
        assert np.allclose([x for *_, x in plan], [x for *_, x in ref_plan], rtol=0.03), (n, plan)
    assert not lost
    assert kills >= 20, kills
    assert rolled_back >= 3  # several kills fell inside a flush (a journal was left) and were rolled back
