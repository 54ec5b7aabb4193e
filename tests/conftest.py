"""Fixtures shared by test modules."""

from __future__ import annotations

import fcntl
import gc
import importlib
import json
import os
import sys
from pathlib import Path

import pytest

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
"""One BLAS thread per test process, set before numpy loads: pytest runs three workers on two cores, where
OpenBLAS's own threads only wait for each other (the linear-algebra-heavy files spent half as much CPU again).
Inherited by the workers and every subprocess; an environment that sets it keeps its own."""

os.environ.setdefault("TEXTUAL_FPS", "5")
"""The tests' own Textual apps draw 5 frames a second (the shipped default is 20: ``labctl.tui.FRAME_RATE_HZ``): they
run headless, no one watches their frames, and what the tests assert is the widgets' state and explicit renders and
screenshots. A quarter of the redraws saved about a sixth of the TUI files' CPU. The tests that run the app in a
real terminal or browser (tmux, the served page) start it without this setting (``shipped_environment``)."""

from drivers.sim import RigTwin  # noqa: E402 - numpy loads here, after the settings above

GC_YOUNG_THRESHOLD = 50_000
"""Allocations between collections of the youngest generation in the test process (Python's default: 700)."""


def pytest_collection_finish(session: pytest.Session) -> None:
    """The garbage collector of the test process: what collection built (every module, table and parameter) is
    frozen, never scanned again, and the young generation is collected less often. The suite's numpy-heavy tests
    spent about 7 % of their CPU in collections; no test relies on when garbage is collected."""
    gc.collect()
    gc.freeze()
    gc.set_threshold(GC_YOUNG_THRESHOLD, 50, 100)


@pytest.hookimpl(tryfirst=True)
def pytest_collection(session: pytest.Session) -> None:
    """Each xdist worker of a whole-suite run imports its share of the test modules first (every ``n``-th file,
    from its own index), with its bytecode written, then collects as usual. Every worker imports every test
    module, and pytest's assertion rewriting of them is half of each worker's collection (about 2 s): so each
    module is rewritten once and the other workers load the cached result (the ``__pycache__`` folders, which git
    ignores; pytest checks the source's size and time before using one). Without this the workers, collecting in
    the same order at the same moment, each rewrote every module, also where the environment sets
    PYTHONDONTWRITEBYTECODE (it only stops writing: a cached module is still read)."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    if not worker.startswith("gw") or session.config.args_source != pytest.Config.ArgsSource.TESTPATHS:
        return
    sys.dont_write_bytecode = False
    index, count = int(worker[2:]), int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    for path in sorted(Path(__file__).parent.glob("test_*.py"))[index::count]:
        try:
            importlib.import_module(f"tests.{path.stem}")
        except KeyboardInterrupt:
            raise
        except BaseException:  # noqa: BLE001, S110 - collection imports it again and reports the failure (a skip too)
            pass


def pytest_sessionfinish(session: pytest.Session) -> None:
    """One full collection when the tests are done (finalisers still reported by pytest's unraisable-exception
    check, which is installed until cleanup), then what survived it is frozen: that check's own five collections
    at cleanup then scan only what is new instead of every live object again (about a second per worker)."""
    gc.collect()
    gc.freeze()


HEAVY_FILES = frozenset({"test_discrepancy_workflow.py", "test_uff.py", "test_bad_inputs.py", "test_planning.py",
                         "test_discrepancy_cli.py", "test_springs.py", "test_campaign_safety.py"})
"""Files of five seconds or more in all though none of their tests is ``slow`` (``-p tests.cpu_per_file``): handed
out with the slow ones, so that the last files to finish are short."""


WAITING_SHARE = 3
"""One test file that waits is handed out for every ``WAITING_SHARE`` files handed out in all: three workers on two
cores keep both busy while one of them waits, not while two or three do."""


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The order test files are handed out in (under xdist's per-file distribution, each to the next free worker):
    files that wait on other processes or real time (``waits``) interleaved one in ``WAITING_SHARE`` with the
    computing ones, which come as files with ``slow`` tests and the ``HEAVY_FILES`` first, then the rest, each group
    in its collected order. The waiting overlaps the other workers' computing, and the last files to finish are
    short computing ones."""
    tier: dict[str, int] = {}
    for item in items:
        rank = 0 if item.get_closest_marker("waits") else \
            1 if item.get_closest_marker("slow") or item.path.name in HEAVY_FILES else 2
        tier[item.path.name] = min(rank, tier.get(item.path.name, 2))
    files = list(dict.fromkeys(item.path.name for item in items))
    waiting = [f for f in files if tier[f] == 0]
    computing = sorted((f for f in files if tier[f] > 0), key=lambda f: tier[f])
    order: list[str] = []
    while waiting or computing:
        take_waiting = waiting and (not computing or len(order) % WAITING_SHARE == 0)
        order.append(waiting.pop(0) if take_waiting else computing.pop(0))
    position = {f: i for i, f in enumerate(order)}
    items.sort(key=lambda item: position[item.path.name])


@pytest.fixture
def first_blow_double(monkeypatch):
    """The campaign's first blow is a double hit (a second pulse 100 ms later, 10 % as strong)."""
    original, blows = RigTwin.strike, []

    def strike(self: RigTwin):  # noqa: ANN202
        blows.append(1)
        if len(blows) == 1:
            self.next_blow_double(delay_s=0.1, ratio=0.1)
        return original(self)

    monkeypatch.setattr(RigTwin, "strike", strike)
    return blows


@pytest.fixture(scope="session")
def demo_campaign(tmp_path_factory) -> tuple[Path, dict]:
    """``labctl demo --json`` run once per test session, shared by every test file and every xdist worker (the
    first to ask makes it under a file lock, the others wait for it): its campaign file and printed summary.
    Tests only read the campaign file; they write their own outputs under their own tmp_path."""
    from tests.cli_util import labctl_json

    base = tmp_path_factory.getbasetemp()
    shared = base.parent if base.name.startswith("popen-gw") else base  # xdist: one base per worker, one parent
    out, done = shared / "demo-shared", shared / "demo-shared.json"
    with (shared / "demo-shared.lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.exists():
            summary = labctl_json("demo", "--out", str(out))
            done.write_text(json.dumps(summary), encoding="utf-8")
        return out / "campaign.h5", json.loads(done.read_text(encoding="utf-8"))
