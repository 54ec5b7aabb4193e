"""The live output of ``labctl run``: a progress line (run/step/impact, load, last bounce frequency, ETA) and,
as they arise, every warning in words: a flagged blow, the operator's verdicts with their reasons, a load drift
and what the operator chose, channels left out, what identification could not vouch for."""

from __future__ import annotations

from typing import TextIO

from labctl import events as ev
from labctl.report.notes import check_words


def _eta(seconds: float | None) -> str:
    if seconds is None:
        return "--:--"
    m, s = divmod(int(seconds + 0.5), 60)
    return f"{m // 60:d}:{m % 60:02d}:{s:02d}" if m >= 60 else f"{m:02d}:{s:02d}"


class ProgressPrinter:
    """Event subscriber that prints progress to a stream (a line per step, a carriage-return status line)."""

    def __init__(self, stream: TextIO) -> None:
        self.out = stream
        self.load = float("nan")
        self.bounce = float("nan")
        self.runs = 1
        self.steps_total = 0
        self.tty = hasattr(stream, "isatty") and stream.isatty()
        self.open_line = False  # a carriage-return progress line is on the terminal

    def __call__(self, event: ev.Event) -> None:
        if isinstance(event, ev.CampaignStarted):
            self.runs = event.runs_per_series
            verb = "resuming" if event.resumed else "starting"
            self.out.write(f"{verb} {event.protocol} on {event.backend or 'sim'} → {event.path}\n")
        elif isinstance(event, ev.StepStarted):
            self.steps_total = event.steps_total
        elif isinstance(event, ev.LoadMeasured):
            self.load = event.load_n
        elif isinstance(event, ev.Progress):
            p = event.position
            bounce = "   --  " if self.bounce != self.bounce else f"{self.bounce:7.2f}"  # none before step 1
            line = (f"run {p.run}/{self.runs} · step {p.step}/{self.steps_total} · hit {p.impact} · "
                    f"load {self.load:7.1f} N · bounce {bounce} Hz · "
                    f"{event.impacts_done}/{event.impacts_total} impacts · ETA {_eta(event.eta_s)}")
            self.out.write(("\r" + line) if self.tty else line + "\n")
            self.open_line = self.tty
        elif isinstance(event, ev.StepProcessed):
            self.bounce = event.bounce_hz
            self._line(f"step {event.position.step}: load {event.load_n:.1f} N, bounce {event.bounce_hz:.2f} Hz, "
                       f"k {event.roller_stiffness_n_per_m:.4e} N/m")
            for warning in event.warnings:
                self._line(f"  warning: {warning}")
        elif isinstance(event, ev.ImpactRejected):
            p = event.position
            self._line(f"step {p.step} impact {event.attempt} flagged by the checks "
                       f"({check_words(event.reasons)})")
        elif isinstance(event, ev.Suspended):
            self._line(f"SUSPENDED: {event.reason}")
        elif isinstance(event, ev.Resumed) and event.reason:
            self._line(f"resumed: {event.reason}")
        elif isinstance(event, ev.StepFailed):
            self._line(f"step {event.position.step} not identified: {event.reason}")
        elif isinstance(event, ev.Notice) and (event.level != "info" or event.kind == "verdict"):
            self._line(f"{event.level}: {event.message}")
        elif isinstance(event, ev.CampaignFinished):
            self.out.write(f"finished: {event.status}\n")
        self.out.flush()

    def _line(self, text: str) -> None:
        """A line of its own (ending the progress line first on a terminal)."""
        self.out.write(("\n" if self.open_line else "") + f"  {text}\n")
        self.open_line = False
