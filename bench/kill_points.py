"""Kill-point sweep: a quick_check (8192-sample records) killed by SIGKILL at every STEP-th write call HDF5
makes to the campaign file, then resumed; counts the kills that fell inside a flush (a journal was left) and
the campaigns that resumed to the uninterrupted run's steps with every impact a reader saw after the kill.

    PYTHONPATH=. python bench/kill_points.py [STEP]      (default 3: 225 kill points, a few minutes)

Run by hand (not a test); tests/test_crash_points.py runs 20 of these kills in CI.
"""

from __future__ import annotations

import collections
import sys
import tempfile
from pathlib import Path

import labctl.campaign  # noqa: F401 — imported once, so each forked run starts at once
import labctl.cli.run  # noqa: F401
from labctl.storage.rollback import journal_path
from tests.test_campaign_safety import SMALL
from tests.test_crash_points import _impacts, _kept, _plan, _run


def main(step: int = 3) -> int:
    with tempfile.TemporaryDirectory() as name:
        tmp = Path(name)
        proto = tmp / "small.toml"
        proto.write_text(SMALL, encoding="utf-8")
        argv = ["run", str(proto), "--seed", "11", "--quiet", "--out"]
        code, total = _run([*argv, str(tmp / "ref.h5")], None, tmp)
        ref = [(s, a) for s, a, _ in _plan(tmp / "ref.h5")]
        counts: collections.Counter[str] = collections.Counter()
        for n in range(1, total, step):
            out = tmp / f"k{n}.h5"
            if _run([*argv, str(out)], n, tmp)[0] != -9:
                counts["not killed"] += 1
                continue
            where = "inside a flush" if out.exists() and journal_path(out).exists() else "between flushes"
            before = _impacts(out) if out.exists() else {}
            code, _ = _run([*argv, str(out), "--resume"] if out.exists() else [*argv, str(out)], None, tmp)
            ok = code == 0 and not _kept(before, _impacts(out)) and [(s, a) for s, a, _ in _plan(out)] == ref
            counts[f"{where}: {'resumed, all impacts kept' if ok else 'LOST OR FAILED'}"] += 1
            out.unlink()
    print(f"{total} write calls per run; kill at every {step}th:")
    for what, n in sorted(counts.items()):
        print(f"  {n:4d}  {what}")
    return 0


if __name__ == "__main__":
    sys.exit(main(*(int(a) for a in sys.argv[1:])))
