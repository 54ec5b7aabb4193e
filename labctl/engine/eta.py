"""Time left in a campaign, from measured load-step times.

A load step (loading, settling, its impacts, identification) is the unit of work: the plan says how many
steps the campaign has, the file says how many are done (a resumed campaign's steps count as done), and the
median active time of the steps measured so far says how long one takes. Time spent paused does not count.
A step resumed with some of its blows already stored needs only the rest: it counts as that fraction of a
step, and its time, scaled up to a whole step, is the pace until a whole step of this session is measured.
Before this session has measured a step, the gaps between the stored impacts' timestamps of completed steps
(the campaign's stored pace) stand in; a new campaign shows no estimate until its first step is done, a
resumed one without usable timestamps the impacts' record time (a rough guess). The first estimate from this
session's own pace replaces the stored one outright (a resumed session may go at another pace: another
technician, another rig, a simulated clock); from then on the estimate never rises above the previous one
(counted down) plus the last measured step time, so it does not jump about.
"""

from __future__ import annotations

import statistics
from collections.abc import Iterable
from dataclasses import dataclass, field

from labctl import events as ev
from labctl.storage.store import StepStamp

MIN_ETA_S = 1.0  # shown while work is left, however fast the estimate says it goes


def stored_step_times_s(first_impact_times_s: Iterable[tuple[tuple[int, int], int, float]]) -> list[float]:
    """Durations of completed steps from the time of each step's first impact: ((series, run), step, t).

    The gap between consecutive steps of one repetition is one step's time (loading, settling, impacts)."""
    by_run: dict[tuple[int, int], list[tuple[int, float]]] = {}
    for run, step, t in first_impact_times_s:
        by_run.setdefault(run, []).append((step, t))
    gaps = []
    for steps in by_run.values():
        steps.sort()
        gaps += [b[1] - a[1] for a, b in zip(steps, steps[1:], strict=False) if b[0] == a[0] + 1 and b[1] > a[1]]
    return gaps


@dataclass
class EtaEstimator:
    """Subscribe to the engine's events; ``eta_s(now)`` gives the time left (None when nothing is known).

    ``now`` is the engine clock (``Event.time_s``): seconds since the engine started. With ``impacts_per_step``
    a step resumed with blows already stored counts only for the blows it still needs."""

    steps_total: int
    steps_done: int = 0
    prior_step_s: float | None = None  # a step's time before this session measured one (the stored pace)
    impacts_per_step: int = 0  # 0: unknown, every step counts whole
    step_times_s: list[float] = field(default_factory=list)  # whole steps measured this session
    partial_times_s: list[float] = field(default_factory=list)  # resumed steps, scaled to a whole step
    _step_key: tuple[int, int, int] | None = None
    _step_active_start: float | None = None
    _stored_blows: int = 0  # blows of the current step accepted before this session
    _blow_seen: bool = False
    _steps_seen: int = 0
    _paused_total: float = 0.0
    _paused_at: float | None = None
    _last: tuple[float, float] | None = None  # (eta, active time) of the last estimate from this session's pace
    _finished: bool = False

    def active(self, now: float) -> float:
        """Engine time not spent paused."""
        paused = self._paused_total + (now - self._paused_at if self._paused_at is not None else 0.0)
        return now - paused

    def __call__(self, event: ev.Event) -> None:
        if isinstance(event, ev.Paused) and self._paused_at is None:
            self._paused_at = event.time_s
        elif isinstance(event, ev.Resumed) and self._paused_at is not None:
            self._paused_total += event.time_s - self._paused_at
            self._paused_at = None
        elif isinstance(event, ev.ImpactAcquired):  # rejected blows too: the first one says what was stored
            key = (event.position.series, event.position.run, event.position.step)
            if key == self._step_key and not self._blow_seen:
                self._blow_seen, self._stored_blows = True, max(event.position.impact - 1, 0)
        elif isinstance(event, ev.StepStarted):
            key = (event.position.series, event.position.run, event.position.step)
            if key == self._step_key:
                return
            now = self.active(event.time_s)
            if self._step_key is not None and self._step_active_start is not None:
                self._measured(now - self._step_active_start)
                self.steps_done += 1
            self._step_key, self._step_active_start = key, now
            self._stored_blows, self._blow_seen = 0, False
            self._steps_seen += 1
        elif isinstance(event, ev.CampaignFinished):
            self._finished = True

    def _measured(self, duration_s: float) -> None:
        """File the finished step's time: a whole step, or a resumed one scaled by the blows it still needed."""
        fraction = self._fraction_needed()
        if self._resumed_without_blows():
            return  # stopped after its last blow: only the identification was left, no measure of a step
        if fraction >= 1.0:
            self.step_times_s.append(duration_s)
        elif fraction > 0.0:
            self.partial_times_s.append(duration_s / fraction)

    def _resumed_without_blows(self) -> bool:
        """The session's first step of a resumed campaign took no blow: all of them were stored before."""
        return self._steps_seen == 1 and self.steps_done > 0 and self.impacts_per_step > 0 and not self._blow_seen

    def _fraction_needed(self) -> float:
        """The part of the current step this session has to do (1: all of it; the blows left of a resumed one)."""
        n = self.impacts_per_step
        if n <= 0 or self._stored_blows <= 0:
            return 1.0
        return max(n - self._stored_blows, 0) / n

    @property
    def measured(self) -> bool:
        """Whether the estimate rests on this session's own pace (else on the stored pace or nothing)."""
        return bool(self.step_times_s or self.partial_times_s)

    @property
    def step_s(self) -> float | None:
        """The typical time of one step: the median measured this session (whole steps first), else the prior."""
        if self.step_times_s:
            return statistics.median(self.step_times_s)
        if self.partial_times_s:
            return statistics.median(self.partial_times_s)
        return self.prior_step_s

    def eta_s(self, now: float) -> float | None:
        """Time left: the steps not yet started times a step's time, plus what the current step still needs."""
        step = self.step_s
        if step is None:
            return None
        if self._finished:
            return 0.0
        t = self.active(now)
        remaining = max(self.steps_total - self.steps_done, 1)  # more steps than planned: at least this one
        if self._step_key is None:
            raw = remaining * step
        else:
            in_step = t - self._step_active_start if self._step_active_start is not None else 0.0
            raw = (remaining - 1) * step + max(step * self._fraction_needed() - in_step, 0.0)
        if not self.measured:
            self._last = None
        elif self._last is not None:  # the previous estimate was on this session's pace too: no jumps
            last_eta, last_t = self._last
            latest = (self.step_times_s or self.partial_times_s)[-1]
            raw = min(raw, max(last_eta - (t - last_t), 0.0) + latest)
        eta = max(raw, MIN_ETA_S)
        if self.measured:
            self._last = (eta, t)
        return eta


def campaign_estimator(completed: Iterable[StepStamp], steps_total: int, impacts_per_step: int, record_s: float
                       ) -> EtaEstimator:
    """An estimator for a campaign about to be run or resumed, from the store's completed steps: they count as
    done, and their first impacts' times give a step's time. A new campaign has no estimate until a step is
    measured; a resumed one without usable timestamps starts from the impacts' record time (a rough guess)."""
    stamps = list(completed)
    gaps = stored_step_times_s(((st.series, st.run), st.step, st.first_impact_s) for st in stamps
                               if st.first_impact_s is not None)
    done = len(stamps)
    if gaps:
        return EtaEstimator(steps_total, done, statistics.median(gaps), impacts_per_step)
    if done == 0:  # a new campaign: no estimate until its first step has been measured
        return EtaEstimator(steps_total, done, None, impacts_per_step)
    return EtaEstimator(steps_total, done, impacts_per_step * record_s, impacts_per_step)
