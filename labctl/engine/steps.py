"""One load step: set the load, wait until it is stable, take and store the impacts (with the operator's
verdicts), identify the step through the one step pipeline, store the result.

The runner talks to the engine only through ``Services`` (a Protocol the engine satisfies), so this module
does not import the sequencer, and it keeps no counters: what was taken is what the store holds.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Literal, Protocol

import numpy as np

from drivers.interfaces import REVIEW_CHOICES, ImpactReview, Record, Rig
from labctl import events as ev
from labctl.engine.conditions import Condition, SafePoint, Trip, Where
from labctl.engine.control import RunControl
from labctl.engine.static import static_reading
from labctl.errors import LabctlError
from labctl.physics.rig_config import RigConfig
from labctl.processing import CheckConfig
from labctl.protocol import Protocol as LabProtocol
from labctl.recording import check_record
from labctl.storage.records import OPERATOR, Calibration, ImpactRecord, StepResult, Verdict
from labctl.storage.store import CampaignStore, StepRow

KNOB_TOLERANCE_DEG = 1e-9
"""A knob turn smaller than this (degrees) is no turn: the step is already at its angle (e.g. on resume)."""


class Interlock(LabctlError):
    """A condition stopped the run (e.g. the load cell read more than the cap); the operator was asked to unload."""


class StepProcessor(Protocol):
    """Identifies one step from its stored impacts (``labctl.recording.process_step``)."""

    def __call__(self, records: Sequence[ImpactRecord], rig: RigConfig, checks: CheckConfig) -> StepResult: ...


class Services(Protocol):
    """What a step needs from the engine: configuration, the store, guarded calls, events and prompts."""

    protocol: LabProtocol
    store: CampaignStore
    control: RunControl
    conditions: Sequence[Condition]
    rig_config: RigConfig
    identify_step: StepProcessor

    def call(self, what: str, fn: object, *args: object, timeout_s: object = ..., retries: int | None = None
             ) -> object: ...
    def now(self) -> float: ...
    def emit(self, event: ev.Event) -> None: ...
    def notify(self, level: str, message: str, kind: str = "notice", position: ev.Position | None = None
               ) -> None: ...
    def prompt(self, rig: Rig, message: str, action: str, choices: tuple[str, ...] = ("ok",),
               position: ev.Position | None = None) -> str: ...
    def checkpoint(self, pos: ev.Position) -> None: ...
    def progress(self, pos: ev.Position) -> None: ...
    def acquire(self, rig: Rig, pos: ev.Position) -> Record: ...


def calibration_of(rig: Rig, channels: Sequence[str]) -> Calibration:
    """The DAQ's sensitivities and ranges for a record's channels (None where the DAQ does not say)."""
    by_name = {c.name: c for c in rig.daq.channels}
    force = next((c for c in by_name.values() if c.kind == "force"), None)
    known = [by_name[c] for c in channels if c in by_name]
    complete = len(known) == len(channels)
    return Calibration(force.sensitivity_v_per_unit if force else None, force.range_units if force else None,
                       tuple(c.sensitivity_v_per_unit for c in known) if complete else None,
                       tuple(c.range_units for c in known) if complete else None)


class StepRunner:
    """Runs and resumes the steps of one repetition."""

    def __init__(self, services: Services, rig: Rig, series: int, run: int, cap_n: float) -> None:
        self.e, self.rig, self.series, self.run, self.cap_n = services, rig, series, run, cap_n
        self.checks = services.protocol.checks
        self.rows: dict[int, StepRow] = {}  # the steps identified in this session: what the curve is built from
        self._held: dict[int, ImpactRecord] = {}  # the current step's impacts as stored, by attempt
        self._branch: Literal["loading", "unloading"] = "loading"  # of the spring curve: the last turn's sense

    def completed_load(self, step: int) -> float | None:
        """The recorded load of a step already finished in the file, identified or not (None: still to run)."""
        return self.e.store.step_load(self.series, self.run, step, complete_only=True)

    def read_load_once(self, pos: ev.Position) -> tuple[float, bool]:
        """One load-cell reading as load per roller (the cell carries all rollers), and whether it was stable.

        With ``load_source = "springs"`` the load comes from the knob angle through the rig file's spring curve
        (no load cell is touched): always stable, its 1-σ in ``spring_load``."""
        if self.e.protocol.loading.load_source == "springs":
            load, _ = self.spring_load(pos)
            self.e.emit(ev.LoadMeasured(self.e.now(), pos, load, True))
            return load, True
        reading = self.e.call("load cell", self.rig.load_cell.read)
        load = reading.force_n / self.e.rig_config.roller_count
        self.e.emit(ev.LoadMeasured(self.e.now(), pos, load, reading.stable))
        return load, reading.stable

    def spring_load(self, pos: ev.Position) -> tuple[float, float]:
        """The load per roller at the knob angle now and its 1-σ, from the characterised spring curve."""
        curve = self.e.rig_config.springs
        if curve is None:
            raise LabctlError(f"{self.e.rig_config.source}: no [springs] table for load_source = \"springs\"")
        angle = self.rig.actuator.knob_angle_deg
        problem = curve.check_range(angle)
        if problem:
            raise LabctlError(f"step {pos.step}: {problem}; characterise the springs further or lower the load")
        return curve.load_n(angle, self._branch), curve.load_std_n(angle, self._branch)

    def read_load(self, pos: ev.Position) -> tuple[float, bool]:
        """Poll the load cell until it reports a stable value (or the settle time runs out)."""
        lo, clock = self.e.protocol.loading, self.rig.clock
        deadline = clock.now() + lo.settle_timeout_s
        while True:
            load, stable = self.read_load_once(pos)
            if stable or clock.now() >= deadline:
                return load, stable
            clock.sleep(lo.settle_poll_s)

    # --- safe points ------------------------------------------------------------------------------------
    def safe_point(self, where: Where, pos: ev.Position, load_n: float | None = None,
                   step_load_n: float | None = None) -> list[Trip]:
        """Check every condition; an interlock unloads and stops, a suspend asks the operator (continue/abort).

        Returns the suspend trips the operator chose to continue past.
        """
        point = SafePoint(where, pos, self.cap_n, self.e.protocol.loading.load_tolerance_fraction, load_n,
                          step_load_n)
        passed = []
        for condition in self.e.conditions:
            trip = condition.check(point)
            if trip is None:
                continue
            self.e.emit(ev.Suspended(self.e.now(), pos, trip.message))
            if trip.kind == "interlock":
                self.e.prompt(self.rig, trip.message, "unload", position=pos)
                self.e.call("actuator", self.rig.actuator.turn_knobs, -self.rig.actuator.knob_angle_deg,
                            timeout_s=None, retries=0)
                raise Interlock(trip.message)
            if self.e.prompt(self.rig, trip.message, "confirm", ("continue", "abort"), position=pos) == "abort":
                self.e.control.abort()
                self.e.checkpoint(pos)
            self.e.emit(ev.Resumed(self.e.now(), pos, f"the operator continued past {trip.condition}"))
            passed.append(trip)
        return passed

    # --- the step ---------------------------------------------------------------------------------------
    def run_step(self, step: int, angle_deg: float, steps_estimate: int, attrs: Mapping[str, object] | None = None
                 ) -> float:
        """Run (or finish) a step and return its load (a step that cannot be identified is stored as failed).

        ``attrs`` are stored with the step when it is created (e.g. why an adaptive campaign added it).
        """
        e, pos = self.e, ev.Position(self.series, self.run, step)
        delta = angle_deg - self.rig.actuator.knob_angle_deg
        expected = e.rig_config.preload_per_roller_n + angle_deg * e.rig_config.load_per_knob_degree_n
        e.emit(ev.StepStarted(e.now(), pos, steps_estimate, angle_deg, expected))
        if abs(delta) > KNOB_TOLERANCE_DEG:  # a manual actuator asks the technician, who may take as long as needed
            e.call("actuator", self.rig.actuator.turn_knobs, delta, timeout_s=None, retries=0)
            self._branch = "loading" if delta > 0 else "unloading"
        load, stable = self.read_load(pos)
        self.safe_point("before_step", pos, load_n=load)
        if e.store.step_load(self.series, self.run, step) is None:
            source: dict[str, object] = {"load_source": e.protocol.loading.load_source}
            if e.protocol.loading.load_source == "springs":
                source.update(load_std_n=self.spring_load(pos)[1], spring_branch=self._branch)
            e.store.step(self.series, self.run, step, {
                "knob_angle_deg": angle_deg, "load_n": load, "load_total_n": load * e.rig_config.roller_count,
                "load_stable": stable, "expected_load_n": expected, **static_reading(self, pos), **source,
                **(attrs or {})})
        step_load = e.store.step_load(self.series, self.run, step)
        assert step_load is not None
        if e.protocol.static is not None and not e.protocol.static.hammer:  # the static method alone
            e.store.complete_step(self.series, self.run, step)
            return step_load
        self._take_impacts(step, step_load)
        load_after, _ = self.read_load_once(pos)  # no waiting for stability: drift shows as it is
        trips = self.safe_point("after_step", pos, load_n=load_after, step_load_n=step_load)
        flags = {t.condition: True for t in trips}
        e.store.update_step(self.series, self.run, step, {"load_after_n": load_after, **flags})
        self._identify(step, pos, step_load, angle_deg)
        return step_load

    def _take_impacts(self, step: int, step_load: float) -> None:
        e, acq = self.e, self.e.protocol.acquisition
        self._held = {}
        infos = e.store.impact_infos(self.series, self.run, step)
        attempt = infos[-1].attempt if infos else 0
        while True:
            infos = e.store.impact_infos(self.series, self.run, step)
            accepted = sum(i.accepted for i in infos)
            pos = ev.Position(self.series, self.run, step, accepted + 1)
            e.checkpoint(pos)  # a verdict given while paused applies here
            if self._apply_override(step, attempt):
                continue
            if accepted >= acq.impacts_per_step:
                break
            rejected = len(infos) - accepted
            if rejected > acq.max_rehits:
                e.notify("warning", f"step {step}: {rejected} rejected impacts, more than {acq.max_rehits} re-hits; "
                         "going on with the accepted ones", position=pos)
                break
            self.safe_point("before_impact", pos, step_load_n=step_load)
            record = e.acquire(self.rig, pos)
            attempt += 1
            self._store(step, attempt, record, pos)
            e.progress(pos)

    def _apply_override(self, step: int, attempt: int) -> bool:
        """Apply a pending verdict from the run control to the step's latest impact; True if it changed one."""
        override = self.e.control.take_override()
        if override is None:
            return False
        verdict, target = override
        if target is not None and target != attempt:
            self.e.notify("warning", f"verdict on impact {target} ignored: impact {attempt} was taken since",
                          kind="verdict")
            return False
        infos = self.e.store.impact_infos(self.series, self.run, step)
        latest = next((i for i in infos if i.attempt == attempt), None)
        if latest is None or latest.accepted == verdict:
            return False
        self.e.store.set_verdict(self.series, self.run, step, attempt, Verdict(verdict, OPERATOR, "monitor"))
        self.e.notify("info", f"impact {attempt} of step {step} {'accepted' if verdict else 'rejected'} "
                      "by the operator", kind="verdict")
        return True

    def _store(self, step: int, attempt: int, record: Record, pos: ev.Position) -> None:
        """Check, store and (when the operator reviews) judge one blow; the next is armed only after that."""
        impact = check_record(record, attempt, self.checks, calibration_of(self.rig, record.channels))
        self._held[attempt] = self.e.store.write_impact(self.series, self.run, step, impact)
        stored = self._held[attempt]
        cls = ev.ImpactAcquired if stored.accepted else ev.ImpactRejected
        self.e.emit(cls(self.e.now(), pos, stored, range_use(self.rig, record)))
        verdict = self._review(step, impact, pos)
        if verdict is not None:
            self.e.store.set_verdict(self.series, self.run, step, attempt, verdict)
            if verdict.accepted != impact.accepted:
                verb = "accepted" if verdict.accepted else "rejected"
                self.e.notify("info", f"impact {attempt} of step {step} {verb} by the operator ({verdict.reason})",
                              kind="verdict", position=pos)

    def _review(self, step: int, impact: ImpactRecord, pos: ev.Position) -> Verdict | None:
        """The operator's verdict on a stored blow, when the operator reviews blows (else None)."""
        op, info = self.rig.operator, impact.info
        review = ImpactReview(self.series, self.run, step, impact.attempt, info.checks.accepted, info.checks.reasons,
                              info.checks.peak_force_n, info.checks.pulse_width_s)
        if callable(getattr(op, "review_impact", None)):
            answer = op.review_impact(review)  # type: ignore[attr-defined]
            if answer is None:
                return None
            choice, reason = answer
            self.e.emit(ev.OperatorPrompted(self.e.now(), review.message(), "review_impact", choice, pos))
        elif getattr(op, "reviews_impacts", False):
            choice = self.e.prompt(self.rig, review.message(), "review_impact", REVIEW_CHOICES, position=pos)
            reason = "operator"
        else:
            return None
        return Verdict(choice == "accept", OPERATOR, reason or "operator")

    def step_impacts(self, step: int) -> list[ImpactRecord]:
        """The step's stored impacts with their current verdicts: the records held since they were written,
        read back from the store only when some were taken before a resume."""
        infos = self.e.store.impact_infos(self.series, self.run, step)
        if all(i.attempt in self._held for i in infos):
            return [replace(self._held[i.attempt], info=i) for i in infos]
        return self.e.store.impacts(self.series, self.run, step)

    def _identify(self, step: int, pos: ev.Position, load: float, angle_deg: float) -> None:
        e = self.e
        result = e.identify_step(self.step_impacts(step), e.rig_config, self.checks)
        e.store.write_step_result(self.series, self.run, step, result)
        self.rows[step] = (step, load, angle_deg, result)
        if not result.identified:
            e.emit(ev.StepFailed(e.now(), pos, result.error))
            return
        e.emit(ev.StepProcessed(e.now(), pos, load, result))


def range_use(rig: Rig, record: Record) -> dict[str, float]:
    """Each channel's peak in this blow as a fraction of its range (1.0: at the clipping level)."""
    ranges = {c.name: c.range_units for c in rig.daq.channels if c.range_units > 0}
    use = {c.name: float(np.max(np.abs(record.force_n))) / c.range_units
           for c in rig.daq.channels if c.kind == "force" and c.range_units > 0}
    for name, trace in zip(record.channels, record.accel_m_per_s2, strict=False):
        if name in ranges:
            use[name] = float(np.max(np.abs(trace))) / ranges[name]
    return use
