"""A full disk on a real small file system: `labctl run quick_check` on a tmpfs of 4, 8 and 16 MB, then the
file system enlarged to 64 MB, `--resume`, and `labctl process` compared with the stored stiffness.

    sudo PYTHONPATH=. python bench/disk_full.py [SIZES_MB ...]

Needs root (mount); skips otherwise. CI tests the same path without root with RLIMIT_FSIZE
(tests/test_campaign_safety.py). Prints one row per size: exit code, status, impacts kept, what the run
said, the resume's status and the largest relative difference between stored and reprocessed stiffness.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import h5py


def labctl(*args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    return subprocess.run([sys.executable, "-m", "labctl", *args], capture_output=True, text=True, env=env,
                          timeout=600)


def impacts(path: Path) -> int:
    names: list[str] = []
    with h5py.File(path, "r") as f:
        f.visit(names.append)
    return sum(n.rsplit("/", 1)[-1].startswith("impact_") for n in names)


def one(size_mb: int, root: Path) -> str:
    where = root / f"fs{size_mb}"
    where.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_mb}m", "tmpfs", str(where)]).returncode:
        return f"{size_mb:3d} MB: mount failed"
    try:
        out = where / "c.h5"
        run = labctl("run", "quick_check", "--out", str(out), "--seed", "4", "--quiet")
        said = (run.stdout + run.stderr).strip().splitlines()[-1][:110] if (run.stdout + run.stderr).strip() else ""
        if not out.exists():
            return f"{size_mb:3d} MB: exit {run.returncode}, no file: {said}"
        with h5py.File(out, "r") as f:
            status = str(f.attrs.get("status"))
        kept = impacts(out)
        tb = "Traceback" in run.stderr
        subprocess.run(["mount", "-o", "remount,size=64m", str(where)], check=True)
        resumed = labctl("run", "quick_check", "--out", str(out), "--resume", "--quiet", "--json")
        done = json.loads(resumed.stdout) if resumed.returncode == 0 else {"status": f"exit {resumed.returncode}"}
        processed = labctl("process", str(out), "--json")
        again = {s["step"]: s["roller_stiffness_n_per_m"] for s in json.loads(processed.stdout)["steps"]
                 if not s["error"]} if processed.returncode == 0 else {}
        from labctl.storage import CampaignReader

        with CampaignReader(out) as r:
            stored = {s.step: s.result.roller_stiffness_n_per_m for run_ in r.runs(1) for s in run_.steps
                      if s.result is not None and s.result.identified}
        diff = max((abs(again[k] / v - 1) for k, v in stored.items() if k in again), default=float("nan"))
        agree = stored.keys() == again.keys()
        return (f"{size_mb:3d} MB: exit {run.returncode}, status {status}, {kept} impacts kept, traceback {tb}; "
                f"'{said}' | resume: {done['status']}, {impacts(out)} impacts; process: same steps {agree}, "
                f"max rel. diff {diff:.1e}")
    finally:
        subprocess.run(["umount", str(where)])


def main(sizes: list[int]) -> int:
    if os.geteuid() != 0:
        print("skipped: needs root to mount a tmpfs (CI uses RLIMIT_FSIZE: tests/test_campaign_safety.py)")
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        for size in sizes:
            print(one(size, Path(tmp)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main([int(a) for a in sys.argv[1:]] or [4, 8, 16]))
