"""The technician's application: runs the engine in a thread worker and shows its events as they happen.

Engine events cross to the UI thread with ``post_message`` (thread-safe and non-blocking: the engine never
waits for a redraw); prompts too, in the same queue behind the events, and the engine waits on the request.
Quitting mid-run asks the engine to stop at its next safe point and waits for it: the file stays resumable.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from textual.app import App
from textual.binding import Binding
from textual.message import Message
from textual.worker import Worker, WorkerState

from labctl import events as ev
from labctl.engine import Outcome, RunControl
from labctl.protocol import Protocol
from labctl.tui.dialogs import ConfirmDialog, HelpScreen, PromptDialog, ReviewDialog
from labctl.tui.monitor import MonitorScreen
from labctl.tui.operator import PromptRequest, TuiOperator
from labctl.tui.state import reason_text
from labctl.tui.stepfrf import StepBlows

DEFAULT_AUTO_CONFIRM_S = 3.0


@dataclass
class TuiSettings:
    """What to run and how; ``auto_confirm_s`` None means every prompt waits for the technician."""

    protocol: Protocol | None = None
    backend: str = "sim"
    out: Path | None = None
    resume: bool = False
    autostart: bool = False
    auto_confirm_s: float | None = None
    world: str | None = None
    seed: int | None = None
    rig: str | None = None
    devices: str | None = None
    no_auto_confirm: bool = False  # --no-auto-confirm: the setup screen's auto-confirm box starts unticked
    review_hits: bool = True  # the per-hit gate: every stored blow waits for the technician's verdict
    arm_grace_s: float = 1.0  # after a verdict at the gate, a `p` this soon still pauses before the next arm

    def out_path(self) -> Path:
        """The campaign file: as given, or ``<protocol>-<date>-<time>.h5`` in the working directory."""
        if self.out is None:
            name = self.protocol.name if self.protocol else "campaign"
            self.out = Path(f"{name}-{time.strftime('%Y%m%d-%H%M%S')}.h5")
        return self.out


class EngineEvents(Message):
    """Engine events are waiting in the app's inbox: the UI takes them all at once and draws them once."""


class PromptPosted(Message):
    """An engine prompt handed to the UI thread behind the events posted before it (never ahead of them)."""

    def __init__(self, show: Callable[[PromptRequest], object], request: PromptRequest) -> None:
        super().__init__()
        self.show, self.request = show, request


class LabApp(App[Outcome | None]):
    """``labctl tui``: pick a protocol, run it with live plots and dialogs, browse campaign files."""

    TITLE = "labctl"
    ENABLE_COMMAND_PALETTE = False  # every action has its key (? lists them); the footer keeps its room
    BINDINGS = [
        Binding("s", "start", "start"),
        Binding("p", "pause", "pause/resume"),
        Binding("a", "abort", "abort"),
        Binding("r", "verdict(False)", "reject hit", show=False),  # the gate shows its own y / r
        Binding("y", "verdict(True)", "accept hit", show=False),
        Binding("t", "auto_confirm", "auto"),
        Binding("o", "browse", "open"),
        Binding("q", "quit", "quit"),
        Binding("question_mark", "help", "keys"),
    ]

    def __init__(self, settings: TuiSettings, *, open_path: Path | None = None, watch_path: Path | None = None,
                 watch_interval_s: float = 1.0, subscribers: tuple = ()) -> None:
        super().__init__()
        self.settings, self.open_path, self.extra_subscribers = settings, open_path, tuple(subscribers)
        self.watch_path, self.watch_interval_s = watch_path, watch_interval_s
        self.control = RunControl()
        self.operator = TuiOperator(self._post_prompt, self.show_prompt, self._tell, settings.review_hits,
                                    settings.arm_grace_s, held=lambda: self.control.paused or
                                    bool(self.control.stop_status))
        self.auto_confirm = settings.auto_confirm_s is not None and settings.backend == "sim"
        self.auto_confirm_delay_s = settings.auto_confirm_s if settings.auto_confirm_s is not None \
            else DEFAULT_AUTO_CONFIRM_S
        self.worker: Worker[Outcome] | None = None
        self.outcome: Outcome | None = None
        self.error: str | None = None
        self.quit_when_done = False
        self.rejection = ""  # why the step's latest impact was rejected (titles the next strike prompt)
        self.held_prompt: PromptRequest | None = None  # arrived while the technician answered a question
        self.monitor = MonitorScreen(settings.protocol)
        self.blows = StepBlows()  # the step's blows so far, for the gate's FRF (filled in the engine thread)
        self._inbox: list[ev.Event | str] = []  # engine events and notices not yet on the screen, in order
        self._inbox_lock = threading.Lock()
        self._plan_counters()

    # --- screens --------------------------------------------------------------------------------------------
    def get_default_screen(self) -> MonitorScreen:
        return self.monitor

    def on_ready(self) -> None:
        if self.watch_path is not None:
            from labctl.tui.watcher import WatchScreen

            self.push_screen(WatchScreen(self.watch_path, self.watch_interval_s))
        elif self.open_path is not None:
            self.action_browse(self.open_path)
        elif self.settings.protocol is None:
            from labctl.tui.setup import SetupScreen

            self.push_screen(SetupScreen(self.settings), self._setup_done)
        elif self.settings.autostart:
            self.action_start()
        else:
            self.monitor.log_line(f"{self.settings.protocol.name} on {self.settings.backend}: press s to start")

    def _setup_done(self, settings: TuiSettings | None) -> None:
        if settings is None:
            self.exit()
            return
        self.settings = settings
        self.operator.reviews_hits = settings.review_hits
        self.monitor.protocol = settings.protocol
        self._plan_counters()
        self.auto_confirm = settings.auto_confirm_s is not None and settings.backend == "sim"
        self.action_start()

    def _plan_counters(self) -> None:
        """Show the protocol's totals (series, repetitions, steps, impacts) before the engine starts."""
        protocol = self.settings.protocol
        if protocol is None:
            return
        steps: tuple[int, ...] = ()
        try:
            from labctl.engine.plan import plan_steps
            from labctl.physics.rig_config import load_rig

            rig = load_rig(self.settings.rig)
            steps = tuple(plan_steps(protocol, spec, rig).steps_estimate for spec in protocol.specimens)
        except Exception:  # the engine reports the plan when it starts; the counters wait for it
            steps = ()
        self.monitor.state.plan(len(protocol.specimens), protocol.repetitions.count,
                                protocol.acquisition.impacts_per_step, steps)

    # --- engine ---------------------------------------------------------------------------------------------
    @property
    def running(self) -> bool:
        return self.worker is not None and self.worker.state in (WorkerState.PENDING, WorkerState.RUNNING)

    def action_start(self) -> None:
        if self.running or self.outcome is not None or self.settings.protocol is None:
            return
        self.monitor.set_status("running")
        if self.settings.resume and self.settings.out is not None:
            self.monitor.preload(str(self.settings.out))
        self.refresh_bindings()
        self.worker = self.run_worker(self._run_engine, name="engine", thread=True, exit_on_error=False)

    def _run_engine(self) -> Outcome:
        from labctl.campaign import run_campaign

        s = self.settings
        assert s.protocol is not None
        return run_campaign(s.protocol, out=s.out_path(), backend=s.backend, resume=s.resume, world=s.world,
                            seed=s.seed, rig=s.rig, devices=s.devices, operator=self.operator,
                            subscribers=(self.blows, self._forward, *self.extra_subscribers), control=self.control)

    def _forward(self, event: ev.Event | str) -> None:
        """Queue an event or notice (engine thread); a burst is drawn once. One message is posted per burst, ahead
        of any prompt posted after the events, so a prompt still never reaches the screen before them."""
        with self._inbox_lock:
            self._inbox.append(event)
            first = len(self._inbox) == 1
        if first:
            self.post_message(EngineEvents())

    def on_engine_events(self, message: EngineEvents) -> None:
        with self._inbox_lock:
            events, self._inbox = self._inbox, []
        if not self.monitor.is_attached:  # the app is closing: events still in flight have no screen
            return
        with self.batch_update():
            for e in events:
                if isinstance(e, str):
                    self.monitor.log_line(e, "yellow")
                else:
                    self._show_event(e)

    def _show_event(self, e: ev.Event) -> None:
        if isinstance(e, ev.ImpactRejected):
            self.rejection = reason_text(e.reasons)
        elif isinstance(e, ev.ImpactAcquired | ev.StepStarted):
            self.rejection = ""
        self.monitor.apply(e)
        if isinstance(e, ev.Resumed) and self.control.stop_status:
            self.monitor.set_status("stopping")

    def _post_prompt(self, show: Callable[[PromptRequest], object], request: PromptRequest) -> None:
        """Queue a prompt for the UI thread without waiting for it (the engine then waits on the request): a
        blocking ``call_from_thread`` could jump ahead of the events queued before it, and never returns when
        the app closes first, which left the engine thread (and the process) hanging."""
        if not self.post_message(PromptPosted(show, request)):
            raise RuntimeError("the app is closed")

    def on_prompt_posted(self, message: PromptPosted) -> None:
        message.show(message.request)

    def _tell(self, text: str) -> None:
        self._forward(text)  # a notice from the operator: in the same inbox, so in order with the events

    def on_worker_state_changed(self, event: Worker.StateChanged) -> None:
        if event.worker is not self.worker or event.state not in (WorkerState.SUCCESS, WorkerState.ERROR,
                                                                  WorkerState.CANCELLED):
            return
        if event.state == WorkerState.SUCCESS:
            self.outcome = event.worker.result
        else:
            self.error = str(event.worker.error or "cancelled")
            self.monitor.set_status("failed")
            self.monitor.log_line(f"the campaign could not run: {self.error}", "bold red")
            self.notify(self.error, title="campaign failed", severity="error", timeout=30)
        self.refresh_bindings()
        if self.quit_when_done:
            self.exit(self.outcome)

    # --- prompts --------------------------------------------------------------------------------------------
    def show_prompt(self, request: PromptRequest) -> None:
        """Open the dialog for an engine prompt (UI thread); a blow to judge opens the per-hit gate. While a
        question (abort?) is open the prompt waits under it, so a key meant for the question never answers it."""
        if isinstance(self.screen, ConfirmDialog):
            self.held_prompt = request
            return
        if request.done.is_set():  # withdrawn while it waited
            return
        if request.review is not None:
            frf = self.blows.frf_so_far(request.review, self.operator.verdicts(request.review))
            self.push_screen(ReviewDialog(request, self.auto_confirm_after_s, frf))
            if not request.review.checks_accepted:
                self.bell()
            return
        if request.action != "strike":  # the DAQ is not waiting for a blow while the technician reads this
            self.monitor.state.trigger = ""
            self.monitor.refresh_header()
        hint = self.rejection if request.action == "strike" else ""
        self.push_screen(PromptDialog(request, hint, self.auto_confirm_after_s))
        self.bell()

    def auto_confirm_after_s(self) -> float | None:
        """Seconds after which an open prompt takes its first choice by itself (None: wait for a key)."""
        return self.auto_confirm_delay_s if self.auto_confirm else None

    def action_auto_confirm(self) -> None:
        if self.settings.backend != "sim":
            self.notify("auto-confirm is only for the simulated rig: a person turns the knobs", severity="warning")
            return
        self.auto_confirm = not self.auto_confirm
        if isinstance(self.screen, PromptDialog | ReviewDialog):
            self.screen.restart_countdown()
        state = f"on ({self.auto_confirm_delay_s:g} s)" if self.auto_confirm else "off"
        self.monitor.log_line(f"auto-confirm of prompts {state}")

    # --- run control ----------------------------------------------------------------------------------------
    def action_pause(self) -> None:
        if not self.running or self.control.stop_status:
            return
        if self.control.paused:
            self.control.resume()
            self.monitor.set_status("running")
            self.monitor.log_line("resuming")
        else:
            self.control.pause()
            self.operator.wake()
            self.monitor.log_line("pause requested: the engine holds at the next safe point")

    def action_verdict(self, accept: bool) -> None:
        if not self.running:
            return
        if self.operator.reviews_hits:  # the gate judges every blow: y / r mean only that, never a late override
            return
        if self.screen is not self.monitor:  # a dialog is open: y/r never answer it, nor judge a blow behind it
            self.notify("y / r judge a blow in the gate; this dialog takes its digits or Enter (? for the keys)",
                        severity="warning", timeout=4)
            return
        shown = self.monitor.state.last_impact
        self.control.override_last_impact(accept, attempt=shown.attempt if shown else None)
        verb = "accept" if accept else "reject"
        self.monitor.log_line(f"{verb} requested for the step's latest impact (applied at the next safe point)")

    def action_abort(self) -> None:
        """Ask before aborting (``x`` aborts); acquisition pauses at its next safe point until it is answered."""
        self._ask("aborted", ConfirmDialog(
            "Abort the campaign?", "Acquisition is paused. x aborts: it stops here, the file keeps every impact so "
            "far and is marked aborted. n goes on.", yes_key="x", yes_label="abort"))

    def _ask(self, status: str, question: ConfirmDialog) -> None:
        """Put a stopping question; acquisition pauses while it is open, a yes stops the run with ``status``."""
        if not self.running or self.control.stop_status or isinstance(self.screen, ConfirmDialog):
            return
        was_paused = self.control.paused
        self.control.pause()
        self.operator.wake()
        if not was_paused:
            self.monitor.log_line("paused while the question is open")

        def answered(yes: bool | None) -> None:
            if yes:
                self.quit_when_done = status == "interrupted"
                self._stop(status)
            elif not was_paused:
                self.control.resume()
                self.monitor.set_status("running")
                self.monitor.log_line("not stopped: resuming")
            held, self.held_prompt = self.held_prompt, None
            if held is not None:
                self.show_prompt(held)

        self.push_screen(question, answered)

    def _stop(self, status: str) -> None:
        (self.control.abort if status == "aborted" else self.control.stop)()
        self.operator.stop(status)
        self.monitor.set_status("stopping")
        self.monitor.log_line(f"stopping ({status}) after the current impact…", "bold yellow")

    def on_unmount(self) -> None:
        """The screen is going away (also in tests): never leave the engine waiting on a dialog nobody sees (its
        thread may outlive a worker already marked cancelled by the closing app, so this does not ask ``running``)."""
        if self.worker is not None and self.outcome is None:
            self.control.stop()
            self.operator.stop("interrupted")

    async def action_quit(self) -> None:
        """Quit; mid-run it asks first (``q`` again quits), then the engine is stopped cleanly at its next safe
        point (the file stays resumable)."""
        if not self.running:
            self.exit(self.outcome)
            return
        self._ask("interrupted", ConfirmDialog(
            "Quit mid-run?", "Acquisition is paused. q quits: the engine stops here and the file stays resumable "
            "(labctl tui PROTOCOL --out FILE --resume). n goes on.", yes_key="q", yes_label="quit"))

    def action_help(self) -> None:
        if not isinstance(self.screen, HelpScreen):
            self.push_screen(HelpScreen())

    def action_browse(self, path: Path | None = None) -> None:
        from labctl.tui.browser import BrowserScreen

        target = path or (self.outcome.path if self.outcome else None)
        if target is None:
            from labctl.tui.setup import OpenFileScreen

            self.push_screen(OpenFileScreen(), lambda p: self.action_browse(Path(p)) if p else None)
            return
        try:
            screen = BrowserScreen(Path(target))
        except Exception as exc:  # a bad file is reported, never fatal
            self.notify(str(exc), title="cannot open", severity="error", timeout=15)
            return
        self.push_screen(screen)

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        """Footer shows only the keys that do something now."""
        if action == "start":
            return self.settings.protocol is not None and not self.running and self.outcome is None \
                and self.error is None
        if action in ("pause", "abort"):
            return self.running
        if action == "verdict":
            return self.running and not self.operator.reviews_hits
        if action == "auto_confirm":
            return self.settings.backend == "sim" and self.watch_path is None
        return True
