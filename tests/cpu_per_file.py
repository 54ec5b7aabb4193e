"""A pytest plugin that prints, per test file, wall time against the CPU it used: this process's (all threads)
and its finished children's. Wall far above CPU is waiting (sleeps, fixed polls, countdowns).

    PYTHONPATH=$PWD python -m pytest -q -p no:cacheprovider -n 0 -p tests.cpu_per_file tests/test_tui*.py

Only with ``-n 0`` (an xdist worker prints nowhere); CPU of processes not waited for (a tmux server) is not seen.
"""

from __future__ import annotations

import os
import time
from collections import defaultdict

import pytest

_totals: dict[str, list[float]] = defaultdict(lambda: [0.0, 0.0, 0.0, 0])


def _clock() -> tuple[float, float, float]:
    t = os.times()
    return time.perf_counter(), t.user + t.system, t.children_user + t.children_system


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):  # noqa: ANN201
    start = _clock()
    yield
    end = _clock()
    row = _totals[item.nodeid.split("::")[0]]
    for i in range(3):
        row[i] += end[i] - start[i]
    row[3] += 1


def pytest_terminal_summary(terminalreporter) -> None:  # noqa: ANN001
    if not _totals:
        return
    write = terminalreporter.write_line
    write(f"{'file':40s} {'tests':>5s} {'wall s':>7s} {'own CPU s':>9s} {'child CPU s':>11s} {'waiting s':>9s}")
    total = [0.0, 0.0, 0.0, 0]
    for name, (wall, own, child, n) in sorted(_totals.items(), key=lambda kv: -kv[1][0]):
        write(f"{name:40s} {n:5d} {wall:7.1f} {own:9.1f} {child:11.1f} {max(wall - own - child, 0):9.1f}")
        total = [a + b for a, b in zip(total, (wall, own, child, n), strict=True)]
    wall, own, child, n = total
    write(f"{'all':40s} {int(n):5d} {wall:7.1f} {own:9.1f} {child:11.1f} {max(wall - own - child, 0):9.1f}")
