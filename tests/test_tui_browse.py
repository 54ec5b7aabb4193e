"""Opening campaign files in the TUI (runs, steps, impacts, curve against the models) and choosing a protocol."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from labctl.campaign import run_campaign
from labctl.storage import CampaignReader
from labctl.tui import LabApp, TuiSettings
from labctl.tui.browser import BrowserScreen
from labctl.tui.dialogs import ConfirmDialog, PromptDialog
from labctl.tui.plots import StiffnessPlot, TracePlot
from labctl.tui.setup import SetupScreen
from tests.engine_util import quick_check_short
from tests.test_tui import SIZE, wait_for

pytestmark = pytest.mark.slow  # each test runs a campaign through the app

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    path = tmp_path_factory.mktemp("browse") / "qc.h5"
    assert run_campaign(quick_check_short(), out=path, seed=4).status == "complete"
    return path


def tree_nodes(node) -> list:
    out = [node]
    for child in node.children:
        out += tree_nodes(child)
    return out


async def test_browser_lists_runs_steps_impacts_and_shows_the_selection(campaign):
    app = LabApp(TuiSettings(), open_path=campaign)
    with CampaignReader(campaign) as r:
        steps = r.runs(1)[0].steps
        curve = r.curve(1, 1)
    async with app.run_test(size=SIZE) as pilot:
        screen = await wait_for(pilot, lambda: isinstance(app.screen, BrowserScreen) and app.screen)
        tree = await wait_for(pilot, lambda: screen.query("#tree") and screen.query_one("#tree"), what="the tree")
        await wait_for(pilot, lambda: sum(str(n.label).startswith("step ") for n in tree_nodes(tree.root)) >= 3,
                       what="the steps in the tree")
        nodes = tree_nodes(tree.root)
        labels = [str(n.label) for n in nodes]
        step_lines = [t for t in labels if t.startswith("step ")]
        assert len(step_lines) == 3
        for line, step in zip(step_lines, steps, strict=True):
            assert f"{step.result.bounce_hz:.2f} Hz" in line and f"{step.load_n:.1f} N" in line
        assert sum(t.startswith("impact ") for t in labels) == sum(len(s.impacts) for s in steps)
        plot = screen.query_one("#b-stiffness", StiffnessPlot)
        assert plot.point_count() == 3 and plot.runs["run 1"][0] == pytest.approx(list(curve["load_n"]))
        assert "Tripp" in plot.models
        step_node = next(n for n in nodes if n.data == ("step", 1, 1, 1))
        tree.move_cursor(step_node)
        await wait_for(pilot, lambda: str(screen.query_one("#detail").render()).startswith("step 1:"),
                       what="the step's detail")
        detail = str(screen.query_one("#detail").render())
        assert f"bounce {steps[0].result.bounce_hz:.2f} Hz" in detail and detail.startswith("step 1:")
        assert screen.query_one("#b-frf-plot", TracePlot).point_count() > 0
        last = steps[0].impacts[-1]
        step_node.expand()
        await pilot.pause(0.1)
        tree.move_cursor(next(n for n in nodes if n.data == ("impact", 1, 1, 1, last.attempt)))
        force = screen.query_one("#b-force", TracePlot)
        await wait_for(pilot, lambda: force.title_text.startswith(f"impact {last.attempt} "), what="the blow")
        x, f = force.lines["force"]
        assert max(f) == pytest.approx(last.peak_force_n, rel=0.05)
        assert force.title_text == f"impact {last.attempt} (ok)"
        await pilot.press("escape")
        assert not isinstance(app.screen, BrowserScreen)


async def test_setup_screen_runs_the_chosen_shipped_protocol(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    app = LabApp(TuiSettings(seed=1, review_hits=False, no_auto_confirm=True))  # the test answers the prompt
    async with app.run_test(size=SIZE) as pilot:
        screen = await wait_for(pilot, lambda: isinstance(app.screen, SetupScreen) and app.screen)
        options = screen.query_one("#protocols")
        assert {"quick_check", "roller_stiffness", "ball_verification"} <= {
            options.get_option_at_index(i).id for i in range(options.option_count)}
        await pilot.press("enter")  # quick_check is highlighted first
        dialog = await wait_for(pilot, lambda: isinstance(app.screen, PromptDialog) and app.screen)
        assert app.settings.protocol.name == "quick_check" and app.settings.backend == "sim"
        await pilot.press("enter")
        await wait_for(pilot, lambda: app.outcome)
        assert dialog.request.answer == "ok"
    assert app.outcome.status == "complete"
    written = list(tmp_path.glob("quick_check-*.h5"))
    assert len(written) == 1 and str(written[0].name) in app.outcome.path


@pytest.mark.skipif(not (shutil.which("tmux") and shutil.which("labctl")), reason="needs tmux and the labctl script")
def test_tmux_acceptance_shows_step_progress_and_bounce_frequency(tmp_path):
    """Issue 6's check as the technician would run it, in a real (80×24) terminal."""
    session = f"labctl-tui-{os.getpid()}"
    # this checkout's labctl (a running tmux server keeps its own environment, and the labctl script may be
    # another checkout's)
    # --auto-confirm 0.1: the clean blows and the prompts answer themselves at once (the default 3 s countdown,
    # nine times over, is what the test waited for; the countdown itself is test_tui_gate's)
    cmd = (f"env -u TEXTUAL_FPS PYTHONPATH={ROOT} {sys.executable} -m labctl tui protocols/quick_check.toml "
           "--backend sim --autostart --auto-confirm 0.1")
    subprocess.run(["tmux", "new", "-d", "-s", session, "-x", "80", "-y", "24", "-c", str(tmp_path), cmd], check=True)
    def capture() -> str:
        return subprocess.run(["tmux", "capture-pane", "-p", "-t", session], capture_output=True, text=True).stdout

    try:
        pane, deadline = "", time.monotonic() + 120
        while time.monotonic() < deadline:
            pane = capture()
            if "COMPLETE" in pane:
                break
            if "reject (r) or accept anyway" in pane:  # a flagged blow waits for the technician: hit again
                subprocess.run(["tmux", "send-keys", "-t", session, "r"], check=True)
                while capture() == pane and time.monotonic() < deadline:  # taken: the screen changes
                    time.sleep(0.05)
            time.sleep(0.1)
        assert "run 1/1 · step 3/3 · hit 2/2" in pane, pane
        assert re.search(r"bounce \d+\.\d\d Hz", pane), pane
        subprocess.run(["tmux", "send-keys", "-t", session, "q"], check=True)
        gone = time.monotonic() + 10  # the app quits and its session ends with it
        while time.monotonic() < gone and subprocess.run(["tmux", "has-session", "-t", session],
                                                          capture_output=True).returncode == 0:
            time.sleep(0.05)
    finally:
        subprocess.run(["tmux", "kill-session", "-t", session], capture_output=True)
    (written,) = tmp_path.glob("quick_check-*.h5")
    with CampaignReader(written) as r:
        assert r.attrs["status"] == "complete"


@pytest.mark.parametrize("no_auto_confirm", [True, False])
async def test_setup_screen_honours_no_auto_confirm(tmp_path, monkeypatch, no_auto_confirm):
    from textual.widgets import Checkbox

    monkeypatch.chdir(tmp_path)
    # --auto-confirm 0.2: the countdown the box turns on is short (the test waits for it)
    app = LabApp(TuiSettings(seed=1, no_auto_confirm=no_auto_confirm, review_hits=False, auto_confirm_s=0.2))
    async with app.run_test(size=SIZE) as pilot:
        screen = await wait_for(pilot, lambda: isinstance(app.screen, SetupScreen) and app.screen)
        assert screen.query_one("#auto", Checkbox).value is not no_auto_confirm
        await pilot.press("enter")  # quick_check
        request = await wait_for(pilot, lambda: app.operator.history and app.operator.history[0], what="mount")
        assert app.auto_confirm is not no_auto_confirm and request.action == "mount_specimen"
        if no_auto_confirm:
            dialog = await wait_for(pilot, lambda: isinstance(app.screen, PromptDialog) and app.screen)
            await pilot.pause(0.6)  # three auto-confirm delays: the prompt still waits for a key
            assert app.screen is dialog and dialog.request is request and request.answer is None
            await pilot.press("enter")
        await wait_for(pilot, lambda: request.done.is_set(), what="the prompt answered")
        assert request.answer == "ok"  # by itself after the countdown (no key was pressed), or by the Enter above
        await wait_for(pilot, lambda: app.screen is app.monitor, what="the prompt closed")
        await pilot.press("a")  # the rest of the campaign proves nothing more here: abort it (unless it is done)
        await wait_for(pilot, lambda: isinstance(app.screen, ConfirmDialog) or app.outcome, what="the question")
        if isinstance(app.screen, ConfirmDialog):
            await pilot.press("x")
        await wait_for(pilot, lambda: app.outcome, what="the engine to stop")
    assert app.outcome.status in ("aborted", "complete")
