"""The load-drift prompt in the TUI, driven with Pilot on the simulated rig: the springs creep during step 1,
the engine asks whether to continue, the header says the technician is asked (never ARMED), and `1` answers
that question; `y` (the gate's accept) does not, and no stale verdict override reaches the next step. Each test
stops the campaign at the first gate of step 2: what it is about has happened by then.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from drivers.sim import RigTwin
from labctl import events as ev
from labctl.storage import CampaignReader
from labctl.tui import LabApp
from labctl.tui.dialogs import ConfirmDialog, PromptDialog, ReviewDialog
from tests.engine_util import Recorder
from tests.test_tui import SIZE, wait_for
from tests.test_tui_gate import gate_settings, next_dialog

pytestmark = pytest.mark.slow  # each test runs a campaign through the app


@pytest.fixture
def creeping_twin(monkeypatch) -> list[RigTwin]:
    """The springs start to creep (3 N/s per roller) at the campaign's first blow; the twin is handed back."""
    original, twins = RigTwin.strike, []

    def strike(self: RigTwin):  # noqa: ANN202
        if not twins:
            twins.append(self)
            self.set_creep(3.0)
        return original(self)

    monkeypatch.setattr(RigTwin, "strike", strike)
    return twins


async def abort(pilot, app: LabApp) -> None:  # noqa: ANN001
    """Abort from the open gate (a, then x on the question) and wait for the engine to stop."""
    await pilot.press("a")
    await wait_for(pilot, lambda: isinstance(app.screen, ConfirmDialog), what="the abort question")
    await pilot.press("x")
    await wait_for(pilot, lambda: app.outcome, what="the engine to stop")


def drift_prompt(dialog: object) -> bool:
    return isinstance(dialog, PromptDialog) and "drifted" in dialog.request.message


async def test_y_on_the_load_drift_prompt_continues_the_campaign(tmp_path: Path, creeping_twin: list[RigTwin]):
    events = Recorder()
    app = LabApp(gate_settings(tmp_path, no_auto_confirm=True), subscribers=(events,))
    async with app.run_test(size=SIZE) as pilot:
        answered_drift = None
        while True:
            dialog = await next_dialog(pilot, app)
            if app.outcome is not None:
                break
            if drift_prompt(dialog) and answered_drift is None:
                assert dialog.request.choices == ("continue", "abort")
                creeping_twin[0].set_creep(0.0)  # the technician re-tightens the knobs
                assert "WAITING FOR YOU" in app.monitor.state.header_text()  # never ARMED under a prompt
                assert "ARMED" not in app.monitor.state.header_text()
                await pilot.press("y")  # the gate's accept: it does not answer the drift prompt
                await pilot.pause(0.1)
                assert not dialog.closed
                await pilot.press("1")
                await wait_for(pilot, lambda d=dialog: d.closed, what="1 to answer the drift prompt")
                assert dialog.request.answer == "continue"
                answered_drift = dialog.request
                continue
            if isinstance(dialog, ReviewDialog) and answered_drift is not None and dialog.request.review.step > 1:
                await abort(pilot, app)  # step 2 is under way: the rest of the campaign proves nothing more
                break
            if isinstance(dialog, ReviewDialog):
                await pilot.press("y" if dialog.request.review.checks_accepted else "r")
            else:
                await pilot.press("enter")
            await wait_for(pilot, lambda d=dialog: d.closed, what="the dialog to close")
        log = "\n".join(str(line.text) for line in app.monitor.query_one("#log").lines)
    assert answered_drift is not None, "the creep did not trip the load-drift check"
    assert app.outcome.status == "aborted" and events.of(ev.StepProcessed)  # step 1 went on after the drift
    assert "verdict on impact" not in log and "requested for the step's latest impact" not in log
    assert not [e for e in events.of(ev.Notice) if "verdict on impact" in e.message]
    with CampaignReader(tmp_path / "gate.h5") as reader:
        assert any(s.load_drift for s in reader.runs(1)[0].steps)


async def test_a_drift_a_dead_channel_and_an_override_each_appear_live(tmp_path: Path, creeping_twin: list[RigTwin],
                                                                       monkeypatch):
    """What happens at the rig is on the screen when it happens: the drift and the technician's choice, the
    pulled A3X cable in the step's summary, and the rejection of a clean blow with its reason."""
    from tests.test_tui_gate import type_text

    crept = RigTwin.strike

    def strike(self: RigTwin):  # noqa: ANN202 - A3X's cable is pulled from the first blow on
        self.pulled_channel = "A3X"
        return crept(self)

    monkeypatch.setattr(RigTwin, "strike", strike)
    app = LabApp(gate_settings(tmp_path, no_auto_confirm=True))
    headers = set()
    async with app.run_test(size=SIZE) as pilot:
        while True:
            dialog = await next_dialog(pilot, app)
            if app.outcome is not None:
                break
            app.monitor.refresh_header()
            headers.add(app.monitor.state.prompt_text().split(":")[0])
            if drift_prompt(dialog):
                creeping_twin[0].set_creep(0.0)
                await pilot.press("1")
            elif isinstance(dialog, ReviewDialog) and dialog.request.review.step > 1:
                await abort(pilot, app)  # all three happened in step 1: the rest of the campaign adds nothing
                break
            elif isinstance(dialog, ReviewDialog):
                r = dialog.request.review
                if (r.step, r.attempt) == (1, 1) and r.checks_accepted:
                    await pilot.press("r")
                    await wait_for(pilot, lambda d=dialog: d.query_one("#reason").has_focus, what="the reason line")
                    await type_text(pilot, "hammer slipped")
                    await pilot.press("enter")
                else:
                    await pilot.press("y" if r.checks_accepted else "r")
            else:
                await pilot.press("enter")
            await wait_for(pilot, lambda d=dialog: d.closed, what="the dialog to close")
            if app.screen is not dialog:
                app.monitor.refresh_header()
        log = " ".join(" ".join(str(line.text) for line in app.monitor.query_one("#log").lines).split())  # unwrapped
    assert app.outcome.status == "aborted"
    assert {"WAITING FOR YOU", "JUDGE THE BLOW"} <= headers and "ARMED" not in headers
    assert "load drifted from" in log and "resumed: the operator continued past load drift" in log
    assert "dead channel(s) left out: A3X" in log
    assert "rejected by the operator (hammer slipped)" in log
