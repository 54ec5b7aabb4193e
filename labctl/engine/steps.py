"""One load step: set the load, wait until it is stable, take the impacts, identify the modes, store it all."""

from __future__ import annotations

import json
import time
from typing import TYPE_CHECKING

import numpy as np

from drivers.interfaces import Rig
from labctl import events as ev
from labctl.processing import ProcessingError, check_impact, identify
from labctl.recording import store_step_result
from labctl.storage import schema
from labctl.storage.reader import step_impacts
from labctl.storage.writer import ImpactData

if TYPE_CHECKING:
    from labctl.engine.plan import StepPlan
    from labctl.engine.sequencer import Engine
    from labctl.protocol import SpecimenSpec

class StepRunner:
    """Runs and resumes the steps of one repetition."""

    def __init__(self, engine: Engine, rig: Rig, series: int, run: int, spec: SpecimenSpec) -> None:
        self.e, self.rig, self.series, self.run, self.spec = engine, rig, series, run, spec
        self.checks = engine.protocol.checks
        self.channels = {c.name: c for c in rig.daq.channels}

    def _group(self, step: int):  # noqa: ANN202
        rg = self.e.writer.h5[schema.series_name(self.series)][schema.run_name(self.run)]
        return rg.get(schema.step_name(step))

    def completed_load(self, step: int) -> float | None:
        """The recorded load of a step already finished in the file, identified or not (None: still to run)."""
        g = self._group(step)
        return float(g.attrs["load_n"]) if g is not None and g.attrs.get(schema.COMPLETE) else None

    def read_load_once(self, pos: ev.Position) -> tuple[float, bool]:
        """One load-cell reading as load per roller (the cell carries all rollers), and whether it was stable."""
        reading = self.e.call("load cell", self.rig.load_cell.read)
        load = reading.force_n / self.e.rig_config.roller_count
        self.e.emit(ev.LoadMeasured(self.e.now(), pos, load, reading.stable))
        return load, reading.stable

    def read_load(self, pos: ev.Position) -> tuple[float, bool]:
        """Poll the load cell until it reports a stable value (or the settle time runs out)."""
        lo = self.e.protocol.loading
        deadline = time.monotonic() + lo.settle_timeout_s
        while True:
            load, stable = self.read_load_once(pos)
            if stable or time.monotonic() >= deadline:
                return load, stable
            if lo.settle_poll_s:
                time.sleep(lo.settle_poll_s)

    def run_step(self, step: int, angle_deg: float, plan: StepPlan) -> float:
        """Run (or finish) a step and return its load (a step that cannot be identified is stored as failed)."""
        e, pos = self.e, ev.Position(self.series, self.run, step)
        existing = self._group(step)
        delta = angle_deg - self.rig.actuator.knob_angle_deg
        expected = e.rig_config.preload_per_roller_n + angle_deg * e.rig_config.load_per_knob_degree_n
        e.emit(ev.StepStarted(e.now(), pos, plan.steps_estimate, angle_deg, expected))
        if abs(delta) > 1e-9:  # a manual actuator asks the technician, who may take as long as needed
            e.call("actuator", self.rig.actuator.turn_knobs, delta, timeout_s=None, retries=0)
        load, stable = self.read_load(pos)
        self._interlock(load, plan, pos)
        if existing is None or "load_n" not in existing.attrs:
            e.writer.step(self.series, self.run, step, {
                "knob_angle_deg": angle_deg, "load_n": load, "load_total_n": load * e.rig_config.roller_count,
                "load_stable": stable, "expected_load_n": expected})
        step_load = float(self._group(step).attrs["load_n"])
        self._take_impacts(step, pos)
        load_after, _ = self.read_load_once(pos)  # no waiting for stability: drift shows as it is
        self._check_drift(step, step_load, load_after, pos)
        self._identify(step, pos, step_load)
        return step_load

    def _interlock(self, load: float, plan: StepPlan, pos: ev.Position) -> None:
        from labctl.engine.sequencer import Interlock

        limit = plan.cap_n * (1 + self.e.protocol.loading.load_tolerance_fraction)
        if load > limit:
            msg = f"load {load:.1f} N per roller exceeds the cap {plan.cap_n:.1f} N (+tolerance): unload now"
            self.e.emit(ev.Suspended(self.e.now(), pos, msg))
            self.e.prompt(self.rig, msg, "unload")
            self.e.call("actuator", self.rig.actuator.turn_knobs, -self.rig.actuator.knob_angle_deg, timeout_s=None,
                        retries=0)
            raise Interlock(msg)

    def _check_drift(self, step: int, before: float, after: float, pos: ev.Position) -> None:
        tol = self.e.protocol.loading.load_tolerance_fraction
        if abs(after - before) <= tol * before:
            self.e.writer.update_step(self.series, self.run, step, {"load_after_n": after})
            return
        msg = (f"load drifted from {before:.1f} N to {after:.1f} N per roller during the step "
               f"(tolerance {tol:.0%}); check the knobs")
        self.e.emit(ev.Suspended(self.e.now(), pos, msg))
        answer = self.e.prompt(self.rig, msg, "confirm", ("continue", "abort"))
        if answer == "abort":
            self.e.control.abort()
            self.e.checkpoint(pos)
        self.e.writer.update_step(self.series, self.run, step, {"load_after_n": after, "load_drift": True})

    def _take_impacts(self, step: int, pos: ev.Position) -> None:
        e, acq = self.e, self.e.protocol.acquisition
        g = self._group(step)
        attempts = sorted(schema.index_of(k) for k in g if k.startswith("impact_"))
        accepted = sum(1 for k in g if k.startswith("impact_") and g[k].attrs.get("accepted"))
        rejected = len(attempts) - accepted
        attempt = attempts[-1] if attempts else 0
        while True:
            e.checkpoint(ev.Position(self.series, self.run, step, accepted + 1))  # a verdict given while paused
            accepted, rejected = self._apply_override(step, attempt, accepted, rejected)  # applies here
            if accepted >= acq.impacts_per_step:
                break
            if rejected > acq.max_rehits:
                e.notify("warning", f"step {step}: {rejected} rejected impacts, more than {acq.max_rehits} re-hits; "
                         "going on with the accepted ones")
                break
            ipos = ev.Position(self.series, self.run, step, accepted + 1)
            record = e.acquire(self.rig, ipos)
            attempt += 1
            ok = self._store(step, attempt, record, accepted, ipos)
            accepted += ok
            rejected += not ok
            if ok:
                e.impacts_done += 1
            e.progress(ipos)

    def _apply_override(self, step: int, attempt: int, accepted: int, rejected: int) -> tuple[int, int]:
        """Apply a pending operator verdict to the latest impact of this step (kept in the file with the reason)."""
        override = self.e.control.take_override()
        if override is None:
            return accepted, rejected
        verdict, target = override
        if target is not None and target != attempt:
            self.e.notify("warning", f"verdict on impact {target} ignored: impact {attempt} was taken since")
            return accepted, rejected
        g = self._group(step).get(schema.impact_name(attempt)) if attempt else None
        if g is None or bool(g.attrs["accepted"]) == verdict:
            return accepted, rejected
        reasons = [r for r in json.loads(g.attrs.get("reasons", "[]")) if r != "operator_accepted"]
        reasons.append("operator_accepted" if verdict else "operator_rejected")
        g.attrs["accepted"], g.attrs["reasons"] = verdict, json.dumps(reasons)
        self.e.writer.h5.flush()
        verb = "accepted" if verdict else "rejected"
        self.e.notify("info", f"impact {attempt} of step {step} {verb} by the operator")
        if verdict:
            self.e.impacts_done += 1
            return accepted + 1, rejected - 1
        self.e.impacts_done -= 1
        return accepted - 1, rejected + 1

    def _store(self, step: int, attempt: int, record, index: int, pos: ev.Position) -> bool:  # noqa: ANN001
        force = np.asarray(record.force_n, dtype=np.float32).astype(float)
        accel = np.asarray(record.accel_m_per_s2, dtype=np.float32).astype(float)
        ranges = [self.channels[c].range_units for c in record.channels if c in self.channels]
        force_ch = next((c for c in self.channels.values() if c.kind == "force"), None)
        check = check_impact(force, accel, record.sample_rate_hz, index=index,
                             accel_ranges=ranges if len(ranges) == len(record.channels) else None,
                             force_range_n=force_ch.range_units if force_ch else None, config=self.checks)
        clipped = () if "overload" in check.reasons else tuple(f"clipped:{c}" for c in record.clipped)
        reasons = tuple(check.reasons) + clipped
        accepted = bool(check.accepted) and not record.clipped
        calib_accel = {"sensitivity_v_per_unit": [self.channels[c].sensitivity_v_per_unit for c in record.channels
                                                  if c in self.channels], "range_units": ranges}
        calib_force = ({"sensitivity_v_per_unit": force_ch.sensitivity_v_per_unit, "range_units": force_ch.range_units}
                       if force_ch else {})
        self.e.writer.write_impact(self.series, self.run, step, attempt, ImpactData(
            record.sample_rate_hz, force, accel, tuple(record.channels), record.trigger_index, record.timestamp_s,
            accepted, reasons, float(check.peak_force_n), float(check.pulse_width_s), tuple(record.clipped),
            calib_force, calib_accel))
        cls = ev.ImpactAcquired if accepted else ev.ImpactRejected
        self.e.emit(cls(self.e.now(), pos, attempt, accepted, reasons, float(check.peak_force_n),
                        float(check.pulse_width_s), record.sample_rate_hz, force, accel, tuple(record.channels)))
        return accepted

    def _identify(self, step: int, pos: ev.Position, load: float) -> None:
        e = self.e
        data = step_impacts(self._group(step), accepted_only=True)
        try:
            if not data.attempts:
                raise ProcessingError("no accepted impact in this step")
            ident = identify(data.force_n, data.accel_m_per_s2, data.sample_rate_hz, data.channels, e.rig_config,
                             accel_ranges=data.accel_ranges, force_range_n=data.force_range_n, config=self.checks)
        except ProcessingError as exc:
            e.emit(ev.StepFailed(e.now(), pos, str(exc)))
            store_step_result(e.writer, self.series, self.run, step, str(exc), data.attempts)
            return
        store_step_result(e.writer, self.series, self.run, step, ident, data.attempts)
        e.emit(ev.StepProcessed(e.now(), pos, load, ident.bounce_hz, tuple(ident.tilt_hz),
                                ident.roller_stiffness_n_per_m, ident.coherence_at_bounce, ident.frequencies_hz,
                                np.abs(ident.h1), ident.coherence, tuple(ident.channels)))
