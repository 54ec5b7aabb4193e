"""Simulated-clock bench: how much real waiting a simulated campaign asks for, and what it costs in wall time.

Runs ``labctl demo`` in this process with ``time.sleep`` wrapped so that every call is counted (and still
sleeps), then prints the total sleep asked for, the number of calls and the wall time of the run.

    python bench/sim_clock.py [--seed N]

Run by hand (not a test). With the rig's virtual clock the engine's settling polls, trigger timeouts and the
hammer's cadence advance rig time, so the sleep total should stay near zero (issue #30: < 0.5 s).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import tempfile
import time
from pathlib import Path


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()

    from labctl.cli import main as labctl_main

    asked: list[float] = []
    real_sleep = time.sleep

    def counting_sleep(seconds: float) -> None:
        asked.append(float(seconds))
        real_sleep(seconds)

    with tempfile.TemporaryDirectory() as tmp:
        out, table = Path(tmp) / "demo", io.StringIO()
        time.sleep = counting_sleep  # type: ignore[assignment]
        t0 = time.perf_counter()
        try:
            with contextlib.redirect_stdout(table):
                rc = labctl_main(["demo", "--quiet", "--seed", str(args.seed), "--out", str(out)])
        finally:
            time.sleep = real_sleep  # type: ignore[assignment]
        wall = time.perf_counter() - t0
    print(table.getvalue().rstrip())
    print(f"labctl demo (seed {args.seed}): exit {rc}, time.sleep asked {sum(asked):.3f} s in {len(asked)} call(s), "
          f"wall {wall:.1f} s ({sum(asked) / wall:.1%} of it asked as sleep)")
    return rc


if __name__ == "__main__":
    raise SystemExit(main())
