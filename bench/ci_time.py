"""The test command's wall time on this machine, a reference revision against this one, side by side in one run.

Each revision is cloned fresh from this repository into a temporary folder and its ``.ci/run`` (the README's test
command) is timed there, ``--rounds`` times, the revisions alternating so that the machine's drift falls on both.
``.ci/run`` installs the clone it runs in (``pip install -e``); this checkout is installed again at the end.

    python bench/ci_time.py --reference c74b05f --rounds 2

Prints each run (wall, user CPU, pytest's summary line), the ratio of the mean walls, each round's ratio and, from
two rounds on, their mean, spread and one-sided 95 % upper bound (is the ratio at most one half at that level?).
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from scipy.special import stdtrit

ROOT = Path(__file__).resolve().parent.parent


def timed_ci(repo: Path, revision: str, work: Path) -> tuple[float, float, str]:
    """Clone ``revision`` into ``work`` and run its ``.ci/run``: (wall s, user CPU s of its children, last line)."""
    subprocess.run(["git", "clone", "-q", str(repo), str(work)], check=True)
    subprocess.run(["git", "-C", str(work), "checkout", "-q", revision], check=True)
    before, start = os.times(), time.monotonic()
    proc = subprocess.run(["bash", ".ci/run"], cwd=work, env={**os.environ, "CI": "true"},
                          capture_output=True, text=True)
    wall, after = time.monotonic() - start, os.times()
    lines = [ln for ln in proc.stdout.splitlines() if ln.strip()]
    failed = [ln for ln in lines if ln.startswith(("FAILED", "ERROR"))]
    last = lines[-1] if lines else proc.stderr.strip()[-200:]
    return wall, after.children_user - before.children_user, "\n".join([last, *failed])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reference", required=True, help="the revision to compare against (a commit or tag)")
    parser.add_argument("--revision", default="HEAD", help="the revision measured (default: this checkout's HEAD)")
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", args.revision], check=True,
                          capture_output=True, text=True).stdout.strip()
    walls: dict[str, list[float]] = {args.reference: [], head: []}
    try:
        for r in range(1, args.rounds + 1):
            for rev in (args.reference, head):
                with tempfile.TemporaryDirectory() as tmp:
                    wall, user, last = timed_ci(ROOT, rev, Path(tmp) / "clone")
                walls[rev].append(wall)
                print(f"round {r}  {rev:>10}  wall {wall:6.1f} s  user {user:6.1f} s  | {last}", flush=True)
    finally:
        subprocess.run([sys.executable, "-m", "pip", "install", "-q", "-e", f"{ROOT}[test]"], check=False,
                       capture_output=True)
    ref, new = statistics.mean(walls[args.reference]), statistics.mean(walls[head])
    print(f"mean wall: {args.reference} {ref:.1f} s, {head} {new:.1f} s; ratio {new / ref:.3f}")
    ratios = [n / r for r, n in zip(walls[args.reference], walls[head], strict=True)]
    print("each round's ratio: " + ", ".join(f"{q:.3f}" for q in ratios))
    if len(ratios) >= 2:
        mean, sd = statistics.mean(ratios), statistics.stdev(ratios)
        upper = mean + stdtrit(len(ratios) - 1, 0.95) * sd / math.sqrt(len(ratios))
        print(f"ratio {mean:.3f} ± {sd:.3f} (mean ± sd of {len(ratios)} rounds); one-sided 95 % upper bound "
              f"(Student t) {upper:.3f}: {'at most' if upper <= 0.5 else 'not shown to be at most'} half")


if __name__ == "__main__":
    main()
