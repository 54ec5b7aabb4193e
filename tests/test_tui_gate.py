"""The per-hit gate in the TUI, driven with Pilot on the simulated rig: after each stored blow the engine waits
for the technician's verdict; an accepted flagged blow is used, a rejected clean blow is not, and the file
says so (verdict source "operator", the step's used attempts).

The twin does not double-hit by itself; the campaign's first blow is made a double hit through the twin's
test hook (``RigTwin.next_blow_double``) from a wrapper around ``RigTwin.strike``.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import numpy as np
import pytest

from labctl import events as ev
from labctl.storage import CampaignReader
from labctl.tui import LabApp, TuiSettings
from labctl.tui.dialogs import ConfirmDialog, PromptDialog, ReviewDialog
from tests.engine_util import Recorder, quick_check_short
from tests.test_tui import SIZE, wait_for

pytestmark = pytest.mark.slow  # each test runs a campaign through the app

def gate_settings(tmp_path: Path, **kw) -> TuiSettings:
    kw.setdefault("arm_grace_s", 0.0)  # no grace after each verdict: the tests answer at once
    return TuiSettings(protocol=quick_check_short(), out=tmp_path / "gate.h5", seed=2, autostart=True, **kw)


async def next_dialog(pilot, app):
    return await wait_for(pilot, lambda: app.outcome is not None or (
        isinstance(app.screen, PromptDialog | ReviewDialog) and not app.screen.closed and app.screen), what="a dialog")


async def type_text(pilot, text: str) -> None:
    await pilot.press(*["space" if c == " " else c for c in text])


async def test_no_auto_confirm_flagged_hit_waits_accepted_flagged_used_rejected_clean_not(tmp_path,
                                                                                         first_blow_double):
    events = Recorder()
    app = LabApp(gate_settings(tmp_path, no_auto_confirm=True), subscribers=(events,))
    async with app.run_test(size=SIZE) as pilot:
        mount = await next_dialog(pilot, app)
        assert isinstance(mount, PromptDialog) and mount.request.action == "mount_specimen"
        await pilot.press("enter")
        gate = await next_dialog(pilot, app)
        assert isinstance(gate, ReviewDialog)
        review = gate.request.review
        assert (review.step, review.attempt) == (1, 1) and "double_hit" in review.reasons
        assert "FLAGGED (double hit)" in str(gate.query_one(".title").render())
        assert app.operator.pending is gate.request  # the engine thread waits on this very verdict
        await pilot.pause(0.2)  # nobody answers: the engine must not arm the next blow
        assert len(events.of(ev.ImpactAcquired)) == 1 and app.screen is gate and not gate.request.done.is_set()
        await pilot.press("y")  # accept the flagged blow: an override needs a reason
        await pilot.press("enter")
        assert not gate.request.done.is_set() and "needs a reason" in str(gate.query_one("#countdown").render())
        await type_text(pilot, "second pulse harmless")
        await pilot.press("enter")
        answered = {(1, 1): "accept"}
        while True:
            dialog = await next_dialog(pilot, app)
            if app.outcome is not None:
                break
            if isinstance(dialog, PromptDialog):
                await pilot.press("enter")
                await wait_for(pilot, lambda d=dialog: d.closed, what="the prompt to close")
                continue
            r = dialog.request.review
            if not r.checks_accepted:  # the twin may clip a channel now and then: agree with the checks
                await pilot.press("r")
            elif (r.step, r.attempt) == (2, 1):  # reject a clean blow, with the reason
                await pilot.press("r")
                await type_text(pilot, "slipped")
                await pilot.press("enter")
            else:
                await pilot.press("y")
            await wait_for(pilot, lambda d=dialog: d.closed, what="the verdict to be taken")
            answered[(r.step, r.attempt)] = dialog.request.answer
        assert app.outcome.status == "complete"
    with CampaignReader(tmp_path / "gate.h5") as reader:
        steps = reader.runs(1)[0].steps
        flagged, clean = steps[0].impacts[0], steps[1].impacts[0]
        used = {s.step: s.result.used_attempts for s in steps}
        verdicts = {(s.step, i.attempt): i.verdict for s in steps for i in s.impacts}
    assert "double_hit" in flagged.checks.reasons and not flagged.checks.accepted
    assert flagged.verdict.accepted and flagged.verdict.source == "operator"
    assert flagged.verdict.reason == "second pulse harmless"
    assert clean.checks.accepted and not clean.verdict.accepted and clean.verdict.source == "operator"
    assert clean.verdict.reason == "slipped"
    assert 1 in used[1] and 1 not in used[2] and len(used[2]) == 2
    assert all(v.source == "operator" for v in verdicts.values())  # every blow went through the gate
    assert {k: ("accept" if v.accepted else "reject") for k, v in verdicts.items()} == answered


async def test_auto_accept_takes_clean_hits_after_the_countdown_but_a_flagged_hit_waits(tmp_path, first_blow_double):
    app = LabApp(gate_settings(tmp_path, auto_confirm_s=0.1))
    async with app.run_test(size=SIZE) as pilot:
        gate = await wait_for(pilot, lambda: isinstance(app.screen, ReviewDialog) and app.screen, what="the gate")
        assert not gate.request.review.checks_accepted
        await pilot.pause(0.4)  # four countdowns long: a flagged blow never accepts itself
        assert app.screen is gate and not gate.request.done.is_set()
        assert "never accepts itself" in str(gate.query_one("#countdown").render())
        await pilot.press("r")  # agrees with the checks: no reason asked
        while app.outcome is None:  # clean blows accept themselves; any other flagged one waits for "r"
            await asyncio.sleep(0.05)  # the app draws at its own rate meanwhile (tests/test_tui.py: wait_for)
            if isinstance(app.screen, ReviewDialog) and not app.screen.closed:
                if app.screen.request.review.checks_accepted:
                    assert app.screen.request.review.attempt > 0
                    continue
                await pilot.pause(0.3)  # three countdowns long
                assert not app.screen.request.done.is_set()
                await pilot.press("r")
    assert app.outcome.status == "complete"
    with CampaignReader(tmp_path / "gate.h5") as reader:
        steps = reader.runs(1)[0].steps
        first = steps[0].impacts[0]
        rest = [i for s in steps for i in s.impacts][1:]
    assert not first.verdict.accepted and first.verdict.source == "operator"
    assert first.verdict.reason == "confirmed by the operator: double_hit"
    clean = [i for i in rest if i.checks.accepted]
    flagged = [i for i in rest if not i.checks.accepted]
    assert clean and all(i.verdict.accepted and i.verdict.source == "checks" for i in clean)
    assert all(not i.verdict.accepted and i.verdict.source == "operator" for i in flagged)


async def test_abort_from_the_open_gate_stops_the_engine_and_marks_the_file(tmp_path):
    events = Recorder()
    app = LabApp(gate_settings(tmp_path, no_auto_confirm=True), subscribers=(events,))
    async with app.run_test(size=SIZE) as pilot:
        await next_dialog(pilot, app)
        await pilot.press("enter")  # mount
        gate = await wait_for(pilot, lambda: isinstance(app.screen, ReviewDialog) and app.screen, what="the gate")
        await pilot.press("a")
        await wait_for(pilot, lambda: isinstance(app.screen, ConfirmDialog), what="the abort question")
        await pilot.press("n")  # not aborted: the gate is still waiting, nothing was armed meanwhile
        await wait_for(pilot, lambda: app.screen is gate, what="the gate again")
        assert app.operator.pending is gate.request  # the engine thread still waits on this verdict
        await pilot.pause(0.2)
        assert app.screen is gate and len(events.of(ev.ImpactAcquired)) == 1
        await pilot.press("a")
        await wait_for(pilot, lambda: isinstance(app.screen, ConfirmDialog), what="the abort question")
        await pilot.press("y")  # y is the gate's accept: it never confirms the abort question
        await pilot.pause(0.1)
        assert isinstance(app.screen, ConfirmDialog) and app.outcome is None
        await pilot.press("x")
        await wait_for(pilot, lambda: app.outcome, what="the engine to stop")
    assert app.outcome.status == "aborted" and len(events.of(ev.ImpactAcquired)) == 1
    with CampaignReader(tmp_path / "gate.h5") as reader:
        assert reader.attrs["status"] == "aborted"


async def test_the_gate_shows_the_steps_frf_over_the_accepted_blows_and_the_one_under_review(tmp_path):
    """Each gate draws |H1| and coherence of the step so far: the first blow alone, then both blows (the
    curve changes); with both accepted it is the FRF the step is then identified with."""
    from labctl.tui.plots import TracePlot

    events = Recorder()
    app = LabApp(gate_settings(tmp_path, no_auto_confirm=True), subscribers=(events,))
    async with app.run_test(size=SIZE) as pilot:
        await next_dialog(pilot, app)
        await pilot.press("enter")  # mount
        shown = []
        for attempt in (1, 2):
            gate = await wait_for(pilot, lambda a=attempt: isinstance(app.screen, ReviewDialog) and not
                                  app.screen.closed and app.screen.request.review.attempt == a and app.screen,
                                  what=f"the gate of blow {attempt}")
            assert gate.request.review.checks_accepted, "seed 2's first blows are clean"
            frf = gate.frf
            assert frf is not None and frf.attempts == tuple(range(1, attempt + 1))
            await wait_for(pilot, lambda g=gate: g.is_mounted and g.query("#gate-coh-plot"),
                           what="the gate's plots mounted")  # a loaded machine composes the dialog later
            magnitude = gate.query_one("#gate-frf-plot", TracePlot)
            coherence = gate.query_one("#gate-coh-plot", TracePlot)
            assert magnitude.point_count() > 100 and coherence.point_count() > 100
            assert max(x for xs, _ in magnitude.lines.values() for x in xs) <= 2000.0
            assert f"{attempt} blow" in str(gate.query_one("#gate-frf").border_title)
            shown.append({k: list(v[1]) for k, v in magnitude.lines.items()})
            await pilot.press("y")
            await wait_for(pilot, lambda g=gate: g.closed, what="the verdict")
        assert shown[0].keys() == shown[1].keys() and shown[0] != shown[1]
        step = await wait_for(pilot, lambda: events.of(ev.StepProcessed), what="step 1 identified")
        await pilot.press("a")
        await wait_for(pilot, lambda: isinstance(app.screen, ConfirmDialog), what="the abort question")
        await pilot.press("y")  # y is the gate's accept: it never confirms the abort question
        await pilot.pause(0.1)
        assert isinstance(app.screen, ConfirmDialog) and app.outcome is None
        await pilot.press("x")
        await wait_for(pilot, lambda: app.outcome, what="the engine to stop")
    assert step[0].used_attempts == (1, 2)
    n = frf.frequencies_hz.size
    assert np.allclose(frf.frequencies_hz, step[0].frequencies_hz[:n])
    assert np.allclose(frf.h1_magnitude, step[0].h1_magnitude[:, :n], rtol=1e-5, atol=0)
    assert np.allclose(frf.coherence, step[0].coherence[:, :n], atol=1e-6)


async def test_pause_pressed_just_after_the_verdict_holds_before_the_next_blow_is_armed(tmp_path):
    """Issue 28: `p` 0.3 s after `y` let one more blow be taken. The next blow is armed only after a short
    grace that follows a person's verdict, so the pause is honoured at the engine's next safe point first."""
    assert TuiSettings().arm_grace_s >= 0.5  # the default leaves a technician's reaction time
    events = Recorder()
    # a 3 s grace here: on a loaded machine the `p` pressed 0.3 s after `y` may reach the app a second later
    app = LabApp(gate_settings(tmp_path, no_auto_confirm=True, arm_grace_s=3.0), subscribers=(events,))
    async with app.run_test(size=SIZE) as pilot:
        await next_dialog(pilot, app)
        await pilot.press("enter")  # mount
        gate = await wait_for(pilot, lambda: isinstance(app.screen, ReviewDialog) and app.screen, what="the gate")
        await pilot.press("y" if gate.request.review.checks_accepted else "r")  # agreeing needs no reason
        await pilot.pause(0.3)
        await pilot.press("p")
        await wait_for(pilot, lambda: app.monitor.state.status == "paused", what="the engine to hold")
        await pilot.pause(0.2)  # held: it stays so (events reach the recorder before the engine's Paused)
        taken = len(events.of(ev.ImpactAcquired))
        assert taken == 1, "a blow was armed and taken after the pause was asked for"
        assert "PAUSED" in str(app.monitor.query_one("#header").render())
        await pilot.press("p")  # resume: the next gate opens
        await wait_for(pilot, lambda: len(events.of(ev.ImpactAcquired)) == 2, what="the next blow")
        await pilot.press("a")
        await wait_for(pilot, lambda: isinstance(app.screen, ConfirmDialog), what="the abort question")
        await pilot.press("x")
        await wait_for(pilot, lambda: app.outcome, what="the engine to stop")


async def test_the_gate_opens_only_after_the_screen_has_the_blow_it_asks_about(tmp_path):
    """A prompt travels in the same queue as the engine's events: when the gate opens, the screen already
    shows the blow under review (a blocking call into the UI thread jumped ahead of the queued events), and a
    test that fails with the gate open does not leave the engine thread hanging on a closed app."""
    app = LabApp(gate_settings(tmp_path, no_auto_confirm=True))
    order: list[tuple[int, int | None]] = []
    show = app.operator._show

    def spy(request) -> None:  # noqa: ANN001
        if request.review is not None:
            last = app.monitor.state.last_impact
            order.append((request.review.attempt, last.attempt if last is not None else None))
        show(request)

    app.operator._show = spy
    async with app.run_test(size=SIZE) as pilot:
        await next_dialog(pilot, app)
        await pilot.press("enter")  # mount
        for n in range(3):  # three blows: two of step 1, the first of step 2
            gate = await wait_for(pilot, lambda: isinstance(app.screen, ReviewDialog) and not app.screen.closed
                                  and app.screen, what=f"gate {n + 1}")
            await pilot.press("y" if gate.request.review.checks_accepted else "r")
            await wait_for(pilot, lambda g=gate: g.closed, what="the verdict")
    # closing with the engine waiting on the next gate: it is withdrawn, the engine stops
    assert app.worker is not None and app.worker.state.name in ("SUCCESS", "ERROR", "CANCELLED", "RUNNING")
    assert order and all(review == shown for review, shown in order), order
