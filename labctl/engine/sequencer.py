"""The protocol engine: the paper's §2.3 sequence over instrument interfaces, never losing an impact.

Per step: actuate the load, wait for a stable load-cell reading, record it, arm the DAQ, strike, check the
impact, store it at once, re-hit rejected impacts (bounded), then identify the step from the accepted impacts.
After each repetition the stiffness-vs-load curve is stored. Resuming continues after the last complete impact.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from dataclasses import asdict, dataclass, field

from drivers.errors import DeviceError
from drivers.interfaces import Record, Rig, TriggerSpec
from labctl import events as ev
from labctl.engine.calls import GuardedCaller, HardwareFailure
from labctl.engine.conditions import DEFAULT_CONDITIONS, Condition
from labctl.engine.control import RunControl, StopRequested
from labctl.engine.eta import campaign_estimator
from labctl.engine.plan import AddedStep, StepAdvisor, StepPlan, continue_after, plan_steps
from labctl.engine.runlog import RunLog
from labctl.engine.static import open_sensor, store_static_curve
from labctl.engine.steps import Interlock, StepProcessor, StepRunner
from labctl.errors import InputError, LabctlError
from labctl.physics.references import reference_curves
from labctl.physics.rig_config import RigConfig
from labctl.protocol import Protocol, SpecimenSpec
from labctl.recording import process_step
from labctl.storage.diskspace import DiskFull
from labctl.storage.records import RepetitionCurve
from labctl.storage.specimen import SpecimenRecord
from labctl.storage.store import CampaignStore, StepRow

RigFactory = Callable[[SpecimenSpec, int], Rig]
ADDED_ATTR = "added_steps"
"""Run attribute: JSON list of the steps an adaptive campaign added to the repetition (``AddedStep`` fields)."""
NOTHING_LEFT = "nothing left to do: every repetition of this campaign is complete"
RATE_TOLERANCE = 1e-9
"""Relative difference between the asked and the set sample rate below which the DAQ is said to have obeyed."""
ACQUIRE_GRACE_S = 10.0
"""Time the guarded call allows a DAQ beyond its own trigger timeout before it is declared hung."""


@dataclass
class Outcome:
    """How a run ended; ``curves`` are every finished repetition of the campaign (resumed or not)."""

    status: str
    path: str
    message: str = ""
    curves: list[RepetitionCurve] = field(default_factory=list)


def specimen_record(spec: SpecimenSpec) -> SpecimenRecord:
    """What is stored of a protocol's specimen: its kind and label, the roller's geometry and material, the
    rails and the protocol's limits for it."""
    r = spec.case().roller
    return SpecimenRecord(
        kind=spec.kind, label=spec.label, roller_type=spec.roller_type, ball_diameter_m=spec.ball_diameter_m,
        diameter_m=r.diameter_m, contact_length_m=r.contact_length_m, roller_length_m=r.total_length_m,
        material=r.material.name, youngs_modulus_pa=r.material.youngs_modulus_pa,
        poisson_ratio=r.material.poisson_ratio, hardness_hrc=r.material.hardness_hrc,
        rail_material=spec.rail_material, rail_ra_m=spec.rail_ra_m, max_load_n=spec.max_load_n,
        knob_step_deg=spec.knob_step_deg, **asdict(spec.conditions))


def check_spring_curve(protocol: Protocol, rig_config: RigConfig, plans: Sequence[StepPlan]) -> None:
    """A ``load_source = "springs"`` campaign needs the rig's characterised curve over every planned knob angle."""
    curve = rig_config.springs
    if curve is None:
        raise InputError(f"{protocol.source_path}: loading.load_source = \"springs\" but the rig file "
                         f"{rig_config.source} has no [springs] table: characterise the springs and write it with "
                         "`labctl springs fit` (docs/springs.md)")
    top = max((p.steps_estimate - 1) * p.step_angle_deg for p in plans)
    if top > curve.max_angle_deg * (1 + 1e-9):
        raise InputError(f"{protocol.source_path}: the plan turns the knobs to {top:g}°, beyond the spring curve's "
                         f"characterised {curve.max_angle_deg:g}° ({rig_config.source}): characterise further")


class Engine:
    """Runs a protocol on instruments from ``rig_factory`` and writes everything to ``store`` (an HDF5 file
    through ``CampaignWriter``, or memory)."""

    def __init__(self, protocol: Protocol, rig_config: RigConfig, rig_factory: RigFactory, store: CampaignStore,
                 bus: ev.EventBus | None = None, control: RunControl | None = None,
                 conditions: Sequence[Condition] = (), advisor: StepAdvisor | None = None,
                 budget_steps: int = 0, identify_step: StepProcessor = process_step) -> None:
        """``conditions`` are checked at every safe point after the load interlock and the load-drift check.

        With an ``advisor`` (adaptive campaign), each repetition gets up to ``budget_steps`` extra load steps
        after its base steps, chosen by the advisor from everything measured so far in the file.
        ``identify_step`` turns a step's stored impacts into its result: the one step pipeline, or a script
        when only the engine's logic is under test.
        """
        self.identify_step = identify_step
        self.protocol, self.rig_config, self.rig_factory, self.store = protocol, rig_config, rig_factory, store
        self.conditions: tuple[Condition, ...] = (*DEFAULT_CONDITIONS, *conditions)
        self.bus = bus or ev.EventBus()
        self.control = control or RunControl()
        self.t0 = time.monotonic()
        self.position = ev.Position(1, 0)
        acq = protocol.acquisition
        self.runlog = RunLog(store, lambda m: self.bus.publish(ev.Notice(self.now(), "error", m, kind="log")))
        self.call = GuardedCaller(acq.timeout_s, acq.retries,
                                  on_retry=lambda m: self.notify("warning", m, kind="retry"))
        self.advisor, self.budget_steps = advisor, budget_steps if advisor is not None else 0
        self.plans = [plan_steps(protocol, s, rig_config) for s in protocol.specimens]
        if protocol.loading.load_source == "springs":
            check_spring_curve(protocol, rig_config, self.plans)
        steps = sum(p.steps_estimate + self.budget_steps for p in self.plans)
        self.impacts_total = steps * protocol.repetitions.count * acq.impacts_per_step
        self.eta = campaign_estimator(store.completed_steps(), steps * protocol.repetitions.count, acq.impacts_per_step,
                                      acq.samples / acq.sample_rate_hz)
        self.bus.subscribe(self.eta)
        self.curves: dict[tuple[int, int], RepetitionCurve] = {}  # the repetitions finished in this session

    # --- events -------------------------------------------------------------------------------------------
    def now(self) -> float:
        return time.monotonic() - self.t0

    def emit(self, event: ev.Event) -> None:
        """Store the event in the file's run log when it is an incident, then deliver it to the subscribers."""
        self.runlog.record(event)
        self.bus.publish(event)

    def notify(self, level: str, message: str, kind: str = "notice", position: ev.Position | None = None) -> None:
        self.emit(ev.Notice(self.now(), level, message, kind, position))

    def prompt(self, rig: Rig, message: str, action: str, choices: tuple[str, ...] = ("ok",),
               position: ev.Position | None = None) -> str:
        answer = rig.operator.prompt(message, choices, action)  # a person may take as long as they need
        self.emit(ev.OperatorPrompted(self.now(), message, action, answer, position))
        return answer

    def where(self) -> str:
        """The position last passed (series, run, step), for a failure's message."""
        p = self.position
        parts = [f"series {p.series}"] + ([f"run {p.run}"] if p.run else []) + ([f"step {p.step}"] if p.step else [])
        return " ".join(parts)

    def checkpoint(self, pos: ev.Position) -> None:
        self.position = pos
        self.control.checkpoint(on_pause=lambda: self.emit(ev.Paused(self.now(), pos)),
                                on_resume=lambda: self.emit(ev.Resumed(self.now(), pos)))

    def progress(self, pos: ev.Position) -> None:
        now = self.now()
        self.emit(ev.Progress(now, pos, self.impacts_done, self.impacts_total, self.eta.eta_s(now)))

    @property
    def impacts_done(self) -> int:
        """Accepted impacts in the store (the store is the only count)."""
        return self.store.accepted_count()

    # --- campaign -----------------------------------------------------------------------------------------
    def run(self) -> Outcome:
        """Run (or continue) the whole campaign; the file's status tells how it ended."""
        resumed = self.store.has_series()
        self.emit(ev.CampaignStarted(self.now(), self.protocol.name, self.store.path,
                                     str(self.store.attrs.get("backend", "")), len(self.protocol.specimens),
                                     self.protocol.repetitions.count, tuple(p.steps_estimate for p in self.plans),
                                     self.protocol.acquisition.impacts_per_step, resumed))
        outcome = Outcome("complete", self.store.path)
        reps = self.protocol.repetitions.count
        if resumed and all(len(self.store.complete_runs(i)) >= reps
                           for i in range(1, len(self.protocol.specimens) + 1)):
            outcome.message = NOTHING_LEFT
        try:
            for index, (spec, plan) in enumerate(zip(self.protocol.specimens, self.plans, strict=True), start=1):
                self._series(index, spec, plan)
        except StopRequested as stop:
            outcome.status, outcome.message = stop.status, f"stopped by request ({stop.status}); resume with --resume"
        except Interlock as exc:
            outcome.status, outcome.message = "interlock", str(exc)
        except DiskFull as exc:  # the file holds every impact but the one in flight: resumable once there is room
            outcome.status, outcome.message = "interrupted", str(exc)
        except (LabctlError, DeviceError) as exc:
            outcome.status, outcome.message = "failed", str(exc)
        except KeyboardInterrupt:
            outcome.status, outcome.message = "interrupted", "interrupted; resume with --resume"
        except Exception as exc:  # e.g. a world law failing at some load: the file says failed, where and why
            outcome.status = "failed"
            outcome.message = (f"failed at {self.where()}: {' '.join(str(exc).split()) or type(exc).__name__}; "
                               "fix the cause, then --resume")
            raise
        finally:
            self.call.close()
            resumed_runs = resumed and any(self.store.complete_runs(i) for i in range(1, len(self.plans) + 1))
            outcome.curves = self.store.curves() if resumed_runs else [self.curves[k] for k in sorted(self.curves)]
            unstored = self.runlog.close()
            if unstored:
                outcome.message = "; ".join(m for m in (outcome.message, unstored) if m)
            self.store.set_status(outcome.status, outcome.message)
            self.emit(ev.CampaignFinished(self.now(), outcome.status, self.store.path, outcome.message))
        return outcome

    def _series(self, index: int, spec: SpecimenSpec, plan: StepPlan) -> None:
        self.store.series(index, specimen_record(spec))
        runs_done = self.store.complete_runs(index)
        if len(runs_done) >= self.protocol.repetitions.count:
            return
        with ExitStack() as stack:
            rig = self.rig_factory(spec, index)
            cell = () if self.protocol.loading.load_source == "springs" else (("load cell", rig.load_cell),)
            for what, inst in (("daq", rig.daq), ("hammer", rig.hammer), *cell, ("actuator", rig.actuator)):
                self.call(f"{what} (open)", inst.__enter__)
                stack.callback(inst.__exit__, None, None, None)
            open_sensor(self, rig, stack)
            acq = self.protocol.acquisition
            fs = self.call("daq", rig.daq.configure, acq.sample_rate_hz, acq.samples)
            if abs(fs - acq.sample_rate_hz) > RATE_TOLERANCE * acq.sample_rate_hz:
                self.notify("info", f"DAQ set the sample rate to {fs:.6g} Hz (asked {acq.sample_rate_hz:g} Hz)",
                            position=ev.Position(index, 0))
            if not self.store.is_mounted(index):
                self.prompt(rig, f"Mount {spec.label} between the rails (rail Ra {spec.rail_ra_m * 1e6:g} µm) and "
                            "set the knobs to the preload", "mount_specimen", position=ev.Position(index, 0))
                self.store.mark_mounted(index)
            for run in range(1, self.protocol.repetitions.count + 1):
                if run in runs_done:
                    continue
                pos = ev.Position(index, run)
                self.checkpoint(pos)
                started = self.store.run_started(index, run)
                if run > 1 and not started:
                    self._unload(rig)
                    self.prompt(rig, f"Lift the upper disc and rotate the rollers about "
                                f"±{self.protocol.repetitions.rotate_rollers_deg:g}°, then lower the disc",
                                "rotate_rollers", position=pos)
                self.store.run(index, run)
                self.emit(ev.RunStarted(self.now(), pos, spec.label))
                self._run(rig, index, run, spec, plan)
            self._unload(rig)

    def _unload(self, rig: Rig) -> None:
        angle = rig.actuator.knob_angle_deg
        if angle:
            self.call("actuator", rig.actuator.turn_knobs, -angle, timeout_s=None, retries=0)

    def _run(self, rig: Rig, series: int, run: int, spec: SpecimenSpec, plan: StepPlan) -> RepetitionCurve:
        steps = StepRunner(self, rig, series, run, plan.cap_n)
        loads: list[float] = []
        step = 1
        while True:
            load = steps.completed_load(step)
            if load is None:
                self.checkpoint(ev.Position(series, run, step))
                load = steps.run_step(step, (step - 1) * plan.step_angle_deg, plan.steps_estimate)
            loads.append(load)
            if not continue_after(loads, plan, self.rig_config, self.protocol.loading.load_tolerance_fraction):
                break
            step += 1
        if self.advisor is not None:
            step = self._added_steps(steps, series, run, spec, step)
        held = [steps.rows.get(n) for n in range(1, step + 1)]
        store_static_curve(self, series, run, step)
        return self._store_curve(series, run, spec, None if None in held else held)  # type: ignore[arg-type]

    def _added_steps(self, steps: StepRunner, series: int, run: int, spec: SpecimenSpec, base_steps: int) -> int:
        """Ask the advisor once per repetition (the answer is stored in the file before the first added step,
        so a resumed campaign runs exactly the steps planned), then run them as ordinary steps; returns the
        repetition's last step."""
        assert self.advisor is not None
        stored = self.store.run_attrs(series, run).get(ADDED_ATTR)
        if stored is None:
            try:
                added = self.advisor.extra_steps(self.store.stiffness_points(), spec, self.budget_steps)
            except LabctlError as exc:
                self.notify("warning", f"no steps added: the planner could not plan ({exc})",
                            position=ev.Position(series, run))
                added = []
            added = added[: self.budget_steps]
            self.store.set_run_attrs(series, run, {ADDED_ATTR: json.dumps([asdict(a) for a in added]),
                                                    "base_steps": base_steps})
        else:
            added = [AddedStep(**a) for a in (json.loads(stored) if isinstance(stored, str) else stored)]
        total = base_steps + len(added)
        for k, a in enumerate(added, start=1):
            step = base_steps + k
            if steps.completed_load(step) is not None:
                continue
            self.checkpoint(ev.Position(series, run, step))
            steps.run_step(step, a.angle_deg, total, {"added_by": "plan", "plan_reason": a.reason,
                                                      "plan_score": a.score, "plan_load_n": a.target_load_n})
        return total

    def _store_curve(self, series: int, run: int, spec: SpecimenSpec, rows: list[StepRow] | None
                     ) -> RepetitionCurve:
        """Store the repetition's curve, built once from the step results this session holds (``rows``; None
        when some steps were finished before a resume: the store builds it from its results)."""
        curve = self.store.store_curve(series, run, rows)
        self.curves[(series, run)] = curve
        refs = reference_curves(spec.case(), spec.kind, curve.load_n) if curve.load_n.size else {}
        self.emit(ev.RunProcessed(self.now(), ev.Position(series, run), spec.label, tuple(curve.load_n),
                                  tuple(curve.stiffness_n_per_m), {k: tuple(v) for k, v in refs.items()}))
        return curve

    def acquire(self, rig: Rig, pos: ev.Position) -> Record:
        """Arm, strike and fetch one record; a missed blow (trigger timeout) is retried a bounded number of times.

        The strike itself has no deadline: a manual hammer waits for the technician.
        """
        acq = self.protocol.acquisition
        trigger = TriggerSpec(acq.trigger_level_n, acq.pretrigger_samples)
        last: Exception | None = None
        for attempt in range(1 + acq.retries):
            self.call("daq (arm)", rig.daq.arm, trigger, retries=0)
            try:
                rig.hammer.strike()
                return self.call("daq (acquire)", rig.daq.acquire, acq.timeout_s,
                                 timeout_s=acq.timeout_s + ACQUIRE_GRACE_S, retries=0)
            except (DeviceError, LabctlError) as exc:
                last = exc
                if attempt < acq.retries:
                    self.notify("warning", f"no usable record ({exc}); hit again ({attempt + 1}/{acq.retries})",
                                kind="retry", position=pos)
        raise HardwareFailure(f"no record after {1 + acq.retries} blow(s): {last}")
