"""A one-line progress display for unattended runs: run/step/impact, load, last bounce frequency, ETA."""

from __future__ import annotations

from typing import TextIO

from labctl import events as ev


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
            line = (f"run {p.run}/{self.runs} · step {p.step}/{self.steps_total} · impact {p.impact} · "
                    f"load {self.load:7.1f} N · bounce {self.bounce:7.2f} Hz · "
                    f"{event.impacts_done}/{event.impacts_total} impacts · ETA {_eta(event.eta_s)}")
            self.out.write(("\r" + line) if self.tty else line + "\n")
        elif isinstance(event, ev.StepProcessed):
            self.bounce = event.bounce_hz
            if self.tty:
                self.out.write("\n")
            self.out.write(f"  step {event.position.step}: load {event.load_n:.1f} N, bounce {event.bounce_hz:.2f} Hz, "
                           f"k {event.roller_stiffness_n_per_m:.4e} N/m\n")
        elif isinstance(event, ev.ImpactRejected):
            self.out.write(f"  impact rejected ({', '.join(event.reasons)}): hitting again\n")
        elif isinstance(event, ev.Suspended | ev.StepFailed):
            self.out.write(f"  {type(event).__name__.lower()}: {getattr(event, 'reason', '')}\n")
        elif isinstance(event, ev.Notice) and event.level != "info":
            self.out.write(f"  {event.level}: {event.message}\n")
        elif isinstance(event, ev.CampaignFinished):
            self.out.write(f"finished: {event.status}\n")
        self.out.flush()
