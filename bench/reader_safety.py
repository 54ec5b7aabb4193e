"""Reader-safety bench: what the structure walk (no external storage, virtual datasets, links or unknown
filters; labctl.storage.safety) costs when a campaign is opened, against reading every impact's traces,
which process, report and export all do, and against the archive's attribute-only open.

    python bench/reader_safety.py [PROTOCOL] [SEED]

Runs PROTOCOL (default quick_check) on the simulated rig into a temporary folder, then times, in one run,
the walk, an open that reads only root attributes (what ``archive index`` does for unchanged files, no walk),
and an open with the walk plus reading every impact. Run by hand (not a test); the ratios are the result.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import h5py

from labctl.campaign import run_campaign
from labctl.storage import CampaignReader
from labctl.storage.safety import check_structure


def best(fn: object, repeat: int = 3) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()  # type: ignore[operator]
        times.append(time.perf_counter() - t)
    return min(times)


def read_all(path: Path) -> int:
    with CampaignReader(path) as r:
        return sum(len(r.impacts(s, run.run, st.step)) for s in r.series_indices() for run in r.runs(s)
                   for st in run.steps)


def main() -> None:
    protocol = sys.argv[1] if len(sys.argv) > 1 else "quick_check"
    seed = int(sys.argv[2]) if len(sys.argv) > 2 else 1
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "c.h5"
        run_campaign(protocol, out=path, backend="sim", seed=seed)
        with h5py.File(path, "r") as h:
            objects: list[str] = []
            h.visit(objects.append)

        def walk() -> None:
            with h5py.File(path, "r") as h:
                check_structure(h)

        def attrs_only() -> None:
            with CampaignReader(path, attrs_only=True) as r:
                r.attrs  # noqa: B018

        t_walk, t_attrs, t_read = best(walk), best(attrs_only), best(lambda: read_all(path))
        print(f"{protocol}: {len(objects)} objects, {read_all(path)} impacts")
        print(f"  structure walk            {t_walk * 1e3:9.1f} ms")
        print(f"  attribute-only open       {t_attrs * 1e3:9.1f} ms")
        print(f"  open + walk + all impacts {t_read * 1e3:9.1f} ms")
        print(f"  walk / reading the impacts = {t_walk / t_read:.3f}; walk / attribute-only open = "
              f"{t_walk / t_attrs:.1f}")


if __name__ == "__main__":
    main()
