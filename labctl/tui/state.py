"""What the technician's screen shows, folded from engine events: position, load, clock, modes and curves.

Kept free of Textual so the header text and the per-step results can be checked without a terminal.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

from labctl import events as ev

REASON_TEXT = {
    "double_hit": "double hit",
    "overload": "overload",
    "pulse_width": "pulse width out of range",
    "low_force": "blow too soft",
    "low_coherence": "low coherence",
    "operator_rejected": "rejected by the operator",
    "operator_accepted": "accepted by the operator",
}


def reason_text(reasons: tuple[str, ...] | list[str]) -> str:
    """Check reasons in the technician's words (``clipped:A1Z`` → ``A1Z clipped``)."""
    out = []
    for r in reasons:
        if r.startswith("clipped:"):
            out.append(f"{r.partition(':')[2]} clipped")
        else:
            out.append(REASON_TEXT.get(r, r.replace("_", " ")))
    return ", ".join(out) or "no reason given"


def blow_reason(reasons: tuple[str, ...]) -> str:
    """Why one unused blow was not used, counted once: the checks' reasons, or the operator's rejection of a blow
    the checks passed (a flagged blow the operator also rejected is counted under the checks' reason)."""
    checks = tuple(r for r in reasons if r not in ("operator_rejected", "operator_accepted"))
    if checks:
        return reason_text(checks)
    return "rejected by the operator" if "operator_rejected" in reasons else "no reason given"


def tilt_text(tilt_hz: tuple[float, ...] | list[float]) -> str:
    """The tilt pair as ``500.5 / 501.4`` (only the frequencies that were found)."""
    return " / ".join(f"{float(t):.1f}" for t in tilt_hz if math.isfinite(float(t))) or "--"


def row_cells(row: StepRow) -> tuple[str, ...]:
    """A step's cells in the on-screen table (run, step, load N, bounce Hz, tilt Hz, stiffness N/µm, coherence)."""
    return (str(row.run), str(row.step), f"{row.load_n:.1f}", f"{row.bounce_hz:.2f}", tilt_text(row.tilt_hz),
            f"{row.stiffness_n_per_m * 1e-6:.2f}", f"{row.coherence:.3f}")


def sigma_text(std_n_per_m: float) -> str:
    """`` ± 0.12`` (N/µm, 1-σ) when the uncertainty is known, else nothing."""
    return f" ± {std_n_per_m * 1e-6:.2f}" if math.isfinite(std_n_per_m) else ""


def clock(seconds: float | None) -> str:
    """``mm:ss`` (``h:mm:ss`` past an hour); ``--:--`` when unknown."""
    if seconds is None or not math.isfinite(seconds):
        return "--:--"
    m, s = divmod(int(max(seconds, 0.0) + 0.5), 60)
    return f"{m // 60:d}:{m % 60:02d}:{s:02d}" if m >= 60 else f"{m:02d}:{s:02d}"


@dataclass
class StepRow:
    """One identified load step as listed on screen."""

    series: int
    run: int
    step: int
    load_n: float
    bounce_hz: float
    tilt_hz: tuple[float, float]
    stiffness_n_per_m: float
    coherence: float


@dataclass
class CampaignState:
    """The running campaign as the screen knows it; ``apply`` takes every event in the order it was emitted."""

    protocol: str = ""
    path: str = ""
    backend: str = ""
    status: str = "idle"  # idle | running | paused | stopping | complete | aborted | interrupted | failed | ...
    series_total: int = 1
    runs_total: int = 1
    impacts_per_step: int = 1
    steps_estimate: tuple[int, ...] = ()
    position: ev.Position = field(default_factory=lambda: ev.Position(0, 0))
    steps_total: int = 0
    load_n: float = math.nan
    impacts_done: int = 0
    impacts_total: int = 0
    eta_s: float | None = None
    message: str = ""
    steps: list[StepRow] = field(default_factory=list)
    curves: dict[tuple[int, int], tuple[tuple[float, ...], tuple[float, ...]]] = field(default_factory=dict)
    references: dict[str, tuple[float, ...]] = field(default_factory=dict)
    started_at: float | None = None  # local monotonic time of the campaign's t = 0
    finished_at: float | None = None
    eta_at: float | None = None
    last_impact: ev.ImpactAcquired | None = None
    last_step: ev.StepProcessed | None = None
    paused_at: float | None = None  # local time the engine paused: the ETA stands still until it resumes
    waiting: str = ""  # what the technician is asked right now (a dialog is open): the header says it
    held: bool = False  # a prompt is open that stops the work (not the per-hit gate): the ETA stands still
    frozen_at: float | None = None  # local time the ETA stopped counting down (paused or held)
    trigger: str = ""  # "armed" (waiting for the blow) | "triggered" (a blow taken, waiting for its verdict) | ""
    rejected: dict[str, int] = field(default_factory=dict)  # why blows were not used, over the campaign → count
    steps_failed: int = 0
    against_models: list[tuple[tuple[float, ...], dict[str, tuple[float, ...]]]] = field(default_factory=list)

    def plan(self, series_total: int, runs_total: int, impacts_per_step: int,
             steps_estimate: tuple[int, ...] = ()) -> None:
        """The counters' totals from the protocol's plan, before the engine reports them."""
        self.series_total, self.runs_total = series_total, runs_total
        self.impacts_per_step, self.steps_estimate = impacts_per_step, tuple(steps_estimate)

    def apply(self, event: ev.Event, now: float | None = None) -> None:
        """Fold one event into the state."""
        now = time.monotonic() if now is None else now
        if isinstance(event, ev.CampaignStarted):
            self.protocol, self.path, self.backend = event.protocol, event.path, event.backend
            self.series_total, self.runs_total = event.series_total, event.runs_per_series
            self.impacts_per_step, self.steps_estimate = event.impacts_per_step, event.steps_estimate
            self.status, self.started_at, self.finished_at = "running", now - event.time_s, None
        elif isinstance(event, ev.RunStarted):
            self.position = event.position
        elif isinstance(event, ev.StepStarted):
            self.position, self.steps_total = event.position, event.steps_total
            self.trigger = "armed"
        elif isinstance(event, ev.LoadMeasured):
            self.load_n = event.load_n
        elif isinstance(event, ev.ImpactAcquired):  # ImpactRejected too
            self.position, self.last_impact, self.trigger = event.position, event, "triggered"
        elif isinstance(event, ev.OperatorPrompted) and event.action == "review_impact":
            self.trigger = "armed"
        elif isinstance(event, ev.StepFailed):
            self.steps_failed += 1
            self.trigger = ""
        elif isinstance(event, ev.Progress):
            self.trigger = "armed" if self.trigger else ""
            self.position, self.impacts_done = event.position, event.impacts_done
            self.impacts_total = event.impacts_total
            self.eta_s, self.eta_at = event.eta_s, now
            if self.frozen_at is not None:  # a fresh estimate while stopped: it stands still from here
                self.frozen_at = now
        elif isinstance(event, ev.StepProcessed):
            self._step(event)
        elif isinstance(event, ev.RunProcessed):
            key = (event.position.series, event.position.run)
            self.curves[key] = (tuple(event.load_n), tuple(event.stiffness_n_per_m))
            self.references = dict(event.reference_n_per_m)
            self.against_models.append((tuple(event.stiffness_n_per_m), dict(event.reference_n_per_m)))
        elif isinstance(event, ev.Paused):
            self.status, self.position = "paused", event.position
            self.paused_at = now if self.paused_at is None else self.paused_at
            self._freeze(now)
        elif isinstance(event, ev.Resumed):
            self.status = "running"
            self.paused_at = None
            self._freeze(now)  # the pause does not count down the ETA
        elif isinstance(event, ev.CampaignFinished):
            self.status, self.message, self.finished_at, self.eta_s = event.status, event.message, now, 0.0
            self.trigger = ""

    def _step(self, event: ev.StepProcessed) -> None:
        p = event.position
        self.last_step, self.trigger = event, ""
        for why in event.rejected.values():
            key = blow_reason(tuple(why.split(", ")) if why else ())
            self.rejected[key] = self.rejected.get(key, 0) + 1
        self.add_row(StepRow(p.series, p.run, p.step, event.load_n, event.bounce_hz,
                             (float(event.tilt_hz[0]), float(event.tilt_hz[1])),
                             event.roller_stiffness_n_per_m, event.coherence_at_bounce))

    def add_row(self, row: StepRow) -> None:
        """Add (or replace) an identified step and extend its run's stiffness curve."""
        key = (row.series, row.run, row.step)
        self.steps = [r for r in self.steps if (r.series, r.run, r.step) != key]
        self.steps.append(row)
        rows = sorted((r for r in self.steps if (r.series, r.run) == key[:2]), key=lambda r: r.step)
        self.curves[key[:2]] = (tuple(r.load_n for r in rows), tuple(r.stiffness_n_per_m for r in rows))

    # --- text -----------------------------------------------------------------------------------------------
    def elapsed_s(self, now: float | None = None) -> float | None:
        if self.started_at is None:
            return None
        end = self.finished_at if self.finished_at is not None else (time.monotonic() if now is None else now)
        return end - self.started_at

    def eta_now_s(self, now: float | None = None) -> float | None:
        """The engine's last ETA, counted down since it arrived, standing still while paused."""
        if self.eta_s is None or self.eta_at is None:
            return None
        if self.finished_at is not None:
            return 0.0
        t = time.monotonic() if now is None else now
        if self.frozen_at is not None:
            t = min(t, self.frozen_at)
        floor = 1.0 if self.eta_s > 0 else 0.0  # work is left until the engine says it is done
        return max(self.eta_s - (t - self.eta_at), floor)

    def hold(self, what: str, freeze: bool, now: float | None = None) -> None:
        """A dialog is open (``what`` it asks; "" when none): the header says so instead of ARMED, and with
        ``freeze`` the ETA stands still until it is answered (the time is added back to the countdown)."""
        self.waiting, self.held = what, freeze
        self._freeze(now)

    def _freeze(self, now: float | None = None) -> None:
        """Stop the ETA's countdown while paused or held; on going on, the stopped time is not counted."""
        now = time.monotonic() if now is None else now
        stopped = self.paused_at is not None or self.held
        if stopped and self.frozen_at is None:
            self.frozen_at = now
        elif not stopped and self.frozen_at is not None:
            if self.eta_at is not None:
                self.eta_at += now - self.frozen_at
            self.frozen_at = None

    @property
    def running(self) -> bool:
        return self.status in ("running", "paused", "stopping")

    def progress_text(self) -> str:
        """``run r/R · step s/S · hit h/I`` (with the series when the protocol has several): the good hit of the
        step being taken (a rejected blow is hit again for the same h); "impact N" always names a blow by its
        number in the step, as stored, so the two never read alike."""
        p = self.position

        def n(value: int) -> str:
            return str(value) if value else "-"

        steps_total = self.steps_total
        if not steps_total and 1 <= p.series <= len(self.steps_estimate):
            steps_total = self.steps_estimate[p.series - 1]
        elif not steps_total and len(set(self.steps_estimate)) == 1:
            steps_total = self.steps_estimate[0]
        parts = [f"series {n(p.series)}/{self.series_total}"] if self.series_total > 1 else []
        parts += [f"run {n(p.run)}/{self.runs_total}", f"step {n(p.step)}/{steps_total or '-'}",
                  f"hit {n(min(p.impact, self.impacts_per_step))}/{self.impacts_per_step}"]
        return " · ".join(parts)

    def counters_text(self, now: float | None = None) -> str:
        """Where the campaign is, the load, the elapsed time and the ETA."""
        load = "--" if math.isnan(self.load_n) else f"{self.load_n:.1f}"
        return (f"{self.progress_text()} · load {load} N · elapsed {clock(self.elapsed_s(now))} · "
                f"ETA {clock(self.eta_now_s(now))}")

    def prompt_text(self) -> str:
        """What the rig and the technician are doing now: asked by a dialog, armed for a blow, or a blow taken."""
        if self.waiting and self.running:
            return self.waiting
        return {"armed": "ARMED: waiting for the blow", "triggered": "TRIGGERED: judge the hit"}.get(
            self.trigger if self.status == "running" else "", "")

    def header_text(self, now: float | None = None) -> str:
        prompt = self.prompt_text()
        return self.counters_text(now) + (f" · {prompt}" if prompt else "")

    def step_summary(self, event: ev.StepProcessed) -> str:
        """One step in a line: used and rejected blows (why), bounce, k ± 1-σ and the per-roller warning."""
        k, sigma = event.roller_stiffness_n_per_m * 1e-6, sigma_text(event.roller_stiffness_std_n_per_m)
        used = len(event.used_attempts)
        rejected = "; ".join(f"impact {a} {blow_reason(tuple(w.split(', ')) if w else ())}"
                             for a, w in sorted(event.rejected.items()))
        text = (f"step {event.position.step}: {used} hits used" + (f", rejected {rejected}" if rejected else "")
                + f" · bounce {event.bounce_hz:.2f} Hz · k {k:.2f}{sigma} N/µm")
        return text + "".join(f" · WARNING: {w}" for w in event.warnings)

    def end_summary(self, labels: dict[str, str] | None = None) -> list[str]:
        """The end of the run: steps done, rejected blows and why, measured stiffness against the models
        (``labels`` names the models as the plots do)."""
        lines = [f"{len(self.steps)} steps identified" + (f", {self.steps_failed} failed" if self.steps_failed else "")]
        if self.rejected:
            lines.append("hits not used: " + ", ".join(f"{n}× {why}" for why, n in
                                                      sorted(self.rejected.items(), key=lambda kv: -kv[1])))
        else:
            lines.append("hits not used: none")
        ratios_by_model: dict[str, list[float]] = {}
        for measured, models in self.against_models:
            for model, values in models.items():
                ratios_by_model.setdefault(model, []).extend(
                    k / v for k, v in zip(measured, values, strict=False) if v and math.isfinite(k * v))
        for model, ratios in ratios_by_model.items():
            if ratios:
                mean = sum(ratios) / len(ratios)
                name = (labels or {}).get(model, model)
                lines.append(f"measured/{name}: {mean:.2f} on average ({min(ratios):.2f}–{max(ratios):.2f})")
        return lines

    def range_text(self, limit: int = 6) -> str:
        """The last blow's range use per channel (peak / range, %), the fullest first; ! at 90 % or more."""
        e = self.last_impact
        if e is None or not e.range_use:
            return ""
        items = sorted(e.range_use.items(), key=lambda kv: -kv[1])[:limit]
        return "range use " + " ".join(f"{name} {u * 100:.0f}%{'!' if u >= 0.9 else ''}" for name, u in items)

    def modes_text(self) -> str:
        """The latest step's bounce and tilt frequencies, stiffness and coherence."""
        s = self.last_step
        if s is None:
            return "bounce -- Hz · tilt -- Hz · k -- N/µm"
        return (f"bounce {s.bounce_hz:.2f} Hz · tilt {tilt_text(s.tilt_hz)} Hz\n"
                f"k {s.roller_stiffness_n_per_m * 1e-6:.2f}{sigma_text(s.roller_stiffness_std_n_per_m)} N/µm"
                f"{' (1σ)' if math.isfinite(s.roller_stiffness_std_n_per_m) else ''} · "
                f"coherence {s.coherence_at_bounce:.3f} "
                f"(step {s.position.step})")
