"""The technician's TUI driven with Textual's Pilot on the simulated rig: progress, pause/resume, dialogs,
the technician's verdict on an impact, a clean quit mid-run, and the committed SVG snapshot of the run screen.
"""

from __future__ import annotations

import asyncio
import html
import os
import re
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from labctl import events as ev
from labctl.campaign import run_campaign
from labctl.engine import StopRequested
from labctl.protocol import load_protocol
from labctl.storage import CampaignReader
from labctl.tui import LabApp, TuiSettings
from labctl.tui.dialogs import ConfirmDialog, PromptDialog
from labctl.tui.plots import StiffnessPlot
from tests.engine_util import Recorder, impact_event, quick_check_short, short_protocol

pytestmark = pytest.mark.slow  # each test runs a campaign through the app

SNAPSHOT = Path(__file__).parent / "snapshots" / "tui_running.svg"
SIZE = (160, 48)


async def wait_for(pilot, condition: Callable[[], object], timeout_s: float = 30.0, what: str = "") -> object:
    """Let the app run until ``condition()`` is truthy (the engine works in its own thread meanwhile). It sleeps
    between looks rather than ``pilot.pause``, which forces a screen update each time: the app draws at its own
    frame rate, and the conditions read the app's state, not its pixels."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        await asyncio.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what or condition}")


def svg_lines(svg: str) -> list[str]:
    """The text rows of a Textual SVG screenshot, top to bottom."""
    rows: dict[float, list[tuple[float, str]]] = {}
    for x, y, text in re.findall(r'<text[^>]*?x="([\d.]+)" y="([\d.]+)"[^>]*>([^<]*)</text>', svg):
        rows.setdefault(float(y), []).append((float(x), html.unescape(text).replace("\xa0", " ")))
    return ["".join(t for _, t in sorted(parts)) for _, parts in sorted(rows.items())]


def panel_titles(lines: list[str]) -> list[str]:
    return sorted({t for line in lines for t in re.findall(r"╭─ ([a-zA-Z ]+?)\b", line)})


def quick_settings(tmp_path: Path, **kw) -> TuiSettings:
    """quick_check (its short-record form) without the per-hit gate (tests/test_tui_gate.py drives the gate)."""
    kw.setdefault("review_hits", False)
    return TuiSettings(protocol=quick_check_short(), out=tmp_path / "qc.h5", seed=1, **kw)


async def test_autostart_quick_check_progress_pause_prompt_and_finish(tmp_path):
    progress = Recorder()
    app = LabApp(quick_settings(tmp_path, autostart=True), subscribers=(progress,))
    async with app.run_test(size=SIZE) as pilot:
        dialog = await wait_for(pilot, lambda: isinstance(app.screen, PromptDialog) and app.screen, what="mount")
        assert dialog.request.action == "mount_specimen" and "roller type 1" in dialog.request.message
        await pilot.press("p")  # pause asked for while the technician still has the dialog open
        await pilot.press("enter")  # the focused first choice: "ok"
        await wait_for(pilot, lambda: app.monitor.state.status == "paused", what="paused")
        held = app.monitor.state.impacts_done
        await pilot.pause(0.2)  # held at a safe point: the events before it are all on the screen already
        assert app.monitor.state.impacts_done == held == 0
        assert "PAUSED" in str(app.monitor.query_one("#header").render())
        await pilot.press("p")
        await wait_for(pilot, lambda: app.outcome, what="the end of the campaign")
        await wait_for(pilot, lambda: app.monitor.state.status == "complete", what="the screen to say so")
        state = app.monitor.state
        assert app.outcome.status == "complete" and state.status == "complete"
        done = [e.impacts_done for e in progress.of(ev.Progress)]
        assert done == list(range(1, 7))  # 3 steps × 2 impacts, one at a time
        assert state.impacts_done == 6 and state.progress_text() == "run 1/1 · step 3/3 · hit 2/2"
        plot = app.monitor.query_one("#stiffness", StiffnessPlot)
        assert plot.point_count() == 3
        assert {"Tripp", "Eq. 5 (Ra 0.2 µm)"} <= set(plot.models)
        loads, ks = plot.runs["run 1"]
        with CampaignReader(tmp_path / "qc.h5") as r:
            curve = r.curve(1, 1)
        assert loads == pytest.approx(list(curve["load_n"]))
        assert ks == pytest.approx(list(curve["stiffness_n_per_m"] / 1e6))  # drawn in N/µm
        prompts = [e for e in progress.of(ev.OperatorPrompted)]
        assert [(p.action, p.answer) for p in prompts] == [("mount_specimen", "ok")]
        assert app.monitor.query_one("#steps").row_count == 3


async def test_running_screen_snapshot_shows_progress_modes_and_curve(tmp_path, monkeypatch):
    """Holds the engine after step 2 to take the SVG snapshot of a campaign in progress."""
    monkeypatch.chdir(tmp_path)
    hold, release = threading.Event(), threading.Event()

    def hold_after_step_2(event: ev.Event) -> None:
        if isinstance(event, ev.StepProcessed) and event.position.step == 2:
            hold.set()
            release.wait(30)

    settings = quick_settings(tmp_path, autostart=True, auto_confirm_s=0.2)
    settings.out = Path("quick_check.h5")
    app = LabApp(settings, subscribers=(hold_after_step_2,))
    async with app.run_test(size=SIZE) as pilot:
        await wait_for(pilot, lambda: hold.is_set() and app.monitor.query_one("#steps").row_count == 2
                       and "FRF step 2" in str(app.monitor.query_one("#frf-panel").border_title))
        await pilot.pause()  # the screen drawn with them
        svg = app.export_screenshot(title="labctl tui: quick_check on the simulated rig")
        release.set()
        await wait_for(pilot, lambda: app.outcome)
    lines = svg_lines(svg)
    text = "\n".join(lines)
    assert "run 1/1 · step 2/3 · hit 2/2" in text and "RUNNING" in text
    assert re.search(r"bounce \d+\.\d\d Hz", text)
    assert "stiffness vs load" in text and "FRF step 2" in text
    if os.environ.get("LABCTL_UPDATE_SNAPSHOTS"):
        SNAPSHOT.parent.mkdir(exist_ok=True)
        SNAPSHOT.write_text(svg, encoding="utf-8")
    committed = svg_lines(SNAPSHOT.read_text(encoding="utf-8"))
    assert panel_titles(committed) == panel_titles(lines), "layout changed: LABCTL_UPDATE_SNAPSHOTS=1 pytest ..."


async def test_rotate_rollers_dialog_between_repetitions_and_operator_verdict(tmp_path):
    """Two repetitions: the rotate-rollers dialog is answered by key; a reject issued while paused after the
    first impact makes the engine hit again and keeps the rejected impact in the file with the reason."""
    paused_once = threading.Event()
    settings = TuiSettings(protocol=short_protocol(max_load=80.0, reps=2), out=tmp_path / "s.h5", seed=2,
                           autostart=True, review_hits=False)
    app = LabApp(settings)

    def pause_after_first_impact(event: ev.Event) -> None:
        if isinstance(event, ev.ImpactAcquired) and not paused_once.is_set():
            paused_once.set()
            app.control.pause()

    app.extra_subscribers = (pause_after_first_impact,)
    async with app.run_test(size=SIZE) as pilot:
        await wait_for(pilot, lambda: isinstance(app.screen, PromptDialog))
        await pilot.press("1")
        await wait_for(pilot, lambda: app.monitor.state.status == "paused")
        await pilot.press("r")
        await pilot.press("p")
        dialog = await wait_for(pilot, lambda: isinstance(app.screen, PromptDialog) and app.screen)
        assert dialog.request.action == "rotate_rollers" and "rotate the rollers" in dialog.request.message
        assert "Rotate the rollers" in str(dialog.query_one(".title").render())
        await pilot.click("#choice-0")
        await wait_for(pilot, lambda: app.outcome)
        log = "\n".join(str(line.text) for line in app.monitor.query_one("#log").lines)
    assert app.outcome.status == "complete"
    assert "rejected by the operator" in log
    with CampaignReader(tmp_path / "s.h5") as r:
        impacts = r.runs(1)[0].steps[0].impacts
    assert len(impacts) == 3 and [i.accepted for i in impacts].count(True) == 2
    assert sum("operator_rejected" in i.reasons for i in impacts) == 1


async def test_quit_with_a_prompt_open_stops_cleanly_and_the_file_resumes(tmp_path):
    app = LabApp(quick_settings(tmp_path, autostart=True))
    async with app.run_test(size=SIZE) as pilot:
        await wait_for(pilot, lambda: isinstance(app.screen, PromptDialog))
        await pilot.press("q")  # with the mount dialog open: quitting mid-run asks first
        await wait_for(pilot, lambda: isinstance(app.screen, ConfirmDialog), what="the quit question")
        assert "QUESTION: Quit mid-run?" in app.monitor.state.header_text()
        await pilot.press("q")  # q again: the prompt is withdrawn, the engine stops
        await wait_for(pilot, lambda: not app.is_running or app.outcome, what="exit")
    assert app.outcome is not None and app.outcome.status == "interrupted"
    with CampaignReader(tmp_path / "qc.h5") as r:
        assert r.attrs["status"] == "interrupted"
    again = run_campaign(quick_check_short(), out=tmp_path / "qc.h5", resume=True)
    assert again.status == "complete" and len(again.curves[0]["load_n"]) == 3


def _hold_after_step_1() -> tuple[threading.Event, threading.Event, Callable[[ev.Event], None]]:
    """A subscriber that holds the engine after step 1 (``hold`` set) until ``release`` is set."""
    hold, release = threading.Event(), threading.Event()

    def hold_after_step_1(event: ev.Event) -> None:
        if isinstance(event, ev.StepProcessed) and event.position.step == 1:
            hold.set()
            release.wait(30)

    return hold, release, hold_after_step_1


@pytest.mark.parametrize("answer", ["n", "x"])
async def test_a_prompt_arriving_under_the_abort_question_waits_for_its_answer(tmp_path, answer):
    """A prompt the engine asked just before the technician pressed abort may reach the screen after the
    question: it must not cover it (the next key would answer the wrong dialog); it opens once the question
    is answered, and on abort it is withdrawn unseen. The engine is held after step 1 and the late prompt is
    asked from another thread through the operator, as the engine asks."""

    hold, release, hold_after_step_1 = _hold_after_step_1()
    app = LabApp(quick_settings(tmp_path, autostart=True, auto_confirm_s=0.1), subscribers=(hold_after_step_1,))
    answers: list[object] = []

    def ask() -> None:
        try:
            answers.append(app.operator.prompt("Turn each knob 180°", ("done",), "load"))
        except StopRequested as exc:
            answers.append(exc)

    async with app.run_test(size=SIZE) as pilot:
        await wait_for(pilot, lambda: hold.is_set() and not isinstance(app.screen, PromptDialog), what="step 1")
        await pilot.press("a")
        await wait_for(pilot, lambda: isinstance(app.screen, ConfirmDialog), what="the abort question")
        app.auto_confirm = False
        asker = threading.Thread(target=ask)
        asker.start()
        await wait_for(pilot, lambda: app.held_prompt, what="the late prompt, held under the question")
        assert isinstance(app.screen, ConfirmDialog) and app.held_prompt is app.operator.pending
        await pilot.press(answer)
        if answer == "n":
            prompt = await wait_for(pilot, lambda: isinstance(app.screen, PromptDialog) and app.screen,
                                    what="the late prompt, once the question is answered")
            assert prompt.request.message == "Turn each knob 180°"
            await pilot.press("enter")
        asker.join(10)
        release.set()
        if answer == "n":
            await pilot.press("q", "q")
        await wait_for(pilot, lambda: app.outcome, what="the engine to stop")
    if answer == "n":
        assert answers == ["done"] and app.outcome.status == "interrupted"
    else:
        assert isinstance(answers[0], StopRequested) and app.outcome.status == "aborted"


async def test_quit_mid_step_then_resume_in_the_tui_shows_the_earlier_steps(tmp_path):
    hold, release, hold_after_step_1 = _hold_after_step_1()
    app = LabApp(quick_settings(tmp_path, autostart=True, auto_confirm_s=0.1), subscribers=(hold_after_step_1,))
    async with app.run_test(size=SIZE) as pilot:
        await wait_for(pilot, hold.is_set)
        await pilot.press("q", "q")
        assert app.monitor.state.status == "stopping" and app.is_running  # waits for the engine's safe point
        release.set()
        await wait_for(pilot, lambda: app.outcome, what="the engine to stop")
    assert app.outcome.status == "interrupted"
    with CampaignReader(tmp_path / "qc.h5") as r:
        assert [s.step for s in r.runs(1)[0].steps if s.result] == [1]

    settings = quick_settings(tmp_path, autostart=True, resume=True)
    resumed = LabApp(settings)
    async with resumed.run_test(size=SIZE) as pilot:
        await wait_for(pilot, lambda: resumed.outcome, what="the resumed campaign")
        await wait_for(pilot, lambda: resumed.monitor.state.status == "complete", what="the screen to say so")
        steps = [(row.run, row.step) for row in resumed.monitor.state.steps]
        plot = resumed.monitor.query_one("#stiffness", StiffnessPlot)
        assert resumed.outcome.status == "complete" and steps == [(1, 1), (1, 2), (1, 3)]
        assert plot.point_count() == 3 and resumed.monitor.query_one("#steps").row_count == 3
        counted = sum(resumed.monitor.state.rejected.values())
    with CampaignReader(tmp_path / "qc.h5") as r:  # the summary covers the whole campaign, not the session
        unused = sum(not o.used for s in r.runs(1)[0].steps for o in s.result.impacts)
    assert counted == unused


async def test_bad_hit_is_obvious_and_titles_the_next_strike_dialog(tmp_path):
    """A rejected impact turns the impact panel red with its reason; a manual strike prompt then says why."""
    import numpy as np

    app = LabApp(TuiSettings(protocol=load_protocol("quick_check"), backend="hw", review_hits=False))
    async with app.run_test(size=SIZE) as pilot:
        force = np.zeros(2048)
        force[300:306] = [50, 200, 250, 200, 50, 0]
        force[900:904] = [40, 90, 40, 0]
        rejected = impact_event(ev.Position(1, 1, 1, 1), 1, ("double_hit",), force, np.zeros((12, 2048)),
                                tuple(f"A{i}{a}" for i in range(1, 5) for a in "XYZ"), peak_force_n=250.0)
        app._forward(rejected)  # as the engine hands an event to the screen
        panel = app.monitor.query_one("#impact-panel")
        await wait_for(pilot, lambda: panel.has_class("-rejected"), what="the red impact panel")
        assert panel.has_class("-rejected") and "REJECTED: double hit" in str(panel.border_title)
        answers: list[str] = []
        ask = threading.Thread(target=lambda: answers.append(app.operator.prompt(
            "Strike the upper disc once", ("done", "cancel"), "strike")))
        ask.start()
        dialog = await wait_for(pilot, lambda: isinstance(app.screen, PromptDialog) and app.screen)
        assert str(dialog.query_one(".title").render()) == "Hit again: double hit"
        assert dialog.auto_delay_s() is None  # the real rig: no auto-confirm, the engine waits for the technician
        await pilot.pause(0.2)
        assert not answers
        await pilot.press("2")
        ask.join(5)
    assert answers == ["cancel"]


@pytest.mark.parametrize("answer", ["n", "x"])
async def test_abort_dialog_pauses_acquisition_until_answered(tmp_path, answer):

    hold, release, hold_after_step_1 = _hold_after_step_1()
    app = LabApp(quick_settings(tmp_path, autostart=True, auto_confirm_s=0.1), subscribers=(hold_after_step_1,))
    async with app.run_test(size=SIZE) as pilot:
        await wait_for(pilot, lambda: hold.is_set() and not isinstance(app.screen, PromptDialog), what="step 1")
        await pilot.press("a")
        await wait_for(pilot, lambda: isinstance(app.screen, ConfirmDialog), what="the abort question")
        release.set()  # the engine goes on to its next safe point and holds there
        await wait_for(pilot, lambda: app.monitor.state.status == "paused", what="the engine to hold")
        held = app.monitor.state.impacts_done
        await pilot.pause(0.2)  # held at a safe point: it stays so while the question is open
        assert app.monitor.state.impacts_done == held and isinstance(app.screen, ConfirmDialog)
        await pilot.press(answer)
        await wait_for(pilot, lambda: app.outcome, what="the end of the campaign")
    assert app.outcome.status == ("complete" if answer == "n" else "aborted")
    with CampaignReader(tmp_path / "qc.h5") as r:
        assert r.attrs["status"] == app.outcome.status
