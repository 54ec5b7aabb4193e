"""``labctl tui --watch FILE``: follows a campaign another process writes, read-only, to its end; the snapshot
reader retries reads that catch a flush half-way; ``--serve`` builds the command each browser session runs."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from labctl.cli.tui import serve_command
from labctl.errors import InputError
from labctl.storage import CampaignReader
from labctl.tui import LabApp, TuiSettings
from labctl.tui.watch import read_snapshot
from labctl.tui.watcher import WatchScreen
from tests.test_tui import SIZE, wait_for

ROOT = Path(__file__).resolve().parents[1]


async def test_watch_follows_a_running_labctl_run_to_complete(tmp_path: Path):
    out = tmp_path / "watched.h5"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "labctl", "run", "quick_check", "--out", str(out), "--quiet",
                             "--seed", "4"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=tmp_path)
    app = LabApp(TuiSettings(), watch_path=out)
    seen: list[str] = []
    try:
        async with app.run_test(size=SIZE) as pilot:
            screen = await wait_for(pilot, lambda: isinstance(app.screen, WatchScreen) and app.screen)
            original = screen.update_from

            def spy(snap, problem):  # noqa: ANN001, ANN202
                seen.append(snap.status if snap is not None else f"unreadable: {problem}")
                original(snap, problem)

            screen.update_from = spy
            await wait_for(pilot, lambda: screen.snapshot is not None and screen.snapshot.finished, timeout_s=240,
                           what="the watched campaign to end")
            header = str(screen.query_one("#w-header").render())
            rows = screen.query_one("#w-steps").row_count
    finally:
        proc.wait(timeout=240)
    assert proc.returncode == 0, proc.stderr.read()
    assert header.startswith("COMPLETE") and "quick_check" in header
    assert "running" in seen, seen  # it followed the campaign while it ran, not only its end
    with CampaignReader(out) as reader:
        stored = [st for run in reader.runs(1) for st in run.steps]
        assert reader.attrs["status"] == "complete"
    assert rows == len(stored)
    snap = read_snapshot(out)
    assert snap.accepted == sum(st.accepted_count for st in stored) and snap.finished


def test_a_missing_or_foreign_file_is_said_and_a_foreign_file_is_not_retried(tmp_path: Path):
    with pytest.raises(InputError, match="not found"):
        read_snapshot(tmp_path / "nope.h5", attempts=2, wait_s=0.0)
    foreign = tmp_path / "foreign.h5"
    import h5py

    h5py.File(foreign, "w").close()
    with pytest.raises(InputError, match="not a labctl campaign"):
        read_snapshot(foreign, attempts=50, wait_s=1.0)  # refused at once, not after 50 s of retries


def test_serve_runs_the_same_tui_command_without_the_serve_options():
    cmd = serve_command(["tui", "--watch", "c.h5", "--serve", "--host", "0.0.0.0", "--port=8080"])
    assert cmd.endswith("-m labctl tui --watch c.h5") and "--serve" not in cmd and "8080" not in cmd
