"""The one step pipeline: check a delivered ``Record`` → store it → identify the step from its stored impacts.

The engine (live), the UFF importer and ``labctl process`` (reprocessing) all call ``check_record`` and
``process_step``, so an impact's stored verdict means the same everywhere: an impact the operator accepted
is used even when a check flagged it; one the operator rejected is never used.
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import UTC, datetime

import numpy as np

from drivers.interfaces import Record
from labctl.physics.rig_config import RigConfig
from labctl.processing import CheckConfig, ProcessingError, check_impact, identify
from labctl.processing.identification import Identification
from labctl.storage.reader import stack_impacts
from labctl.storage.records import (
    CHECKS,
    Calibration,
    CheckSummary,
    ImpactInfo,
    ImpactOutcome,
    ImpactRecord,
    ModeResult,
    StepFrf,
    StepResult,
    Verdict,
    failed_step,
    plain,
    plain_tuple,
)

UNCALIBRATED = Calibration()  # a source that gives no sensitivities or ranges (an imported file)


def check_record(data: Record, attempt: int, checks: CheckConfig, calibration: Calibration = UNCALIBRATED
                 ) -> ImpactRecord:
    """The impact record of one blow as the DAQ (or an imported file) delivered it, with the channels'
    ``calibration`` and the automatic checks' verdict (source "checks"); the traces are kept as delivered."""
    cal = calibration
    ranges = list(cal.accel_range_m_per_s2) if cal.accel_range_m_per_s2 is not None else None
    check = check_impact(np.asarray(data.force_n, dtype=float), np.asarray(data.accel_m_per_s2, dtype=float),
                         data.sample_rate_hz, index=attempt, accel_ranges=ranges, force_range_n=cal.force_range_n,
                         config=checks)
    clipped = () if "overload" in check.reasons else tuple(f"clipped:{c}" for c in data.clipped)
    reasons = (*check.reasons, *clipped)
    accepted = bool(check.accepted) and not data.clipped
    when = datetime.fromtimestamp(data.timestamp_s, UTC) if data.timestamp_s is not None else datetime.now(UTC)
    info = ImpactInfo(attempt, float(data.sample_rate_hz), int(data.trigger_index),
                      when.isoformat(timespec="milliseconds"),
                      CheckSummary(accepted, reasons, float(check.peak_force_n), float(check.pulse_width_s)),
                      Verdict(accepted, CHECKS), tuple(data.clipped))
    return ImpactRecord(info, tuple(data.channels), np.asarray(data.force_n, dtype=float),
                        np.asarray(data.accel_m_per_s2, dtype=float), cal)


def forced_verdicts(records: Sequence[ImpactRecord]) -> list[bool | None]:
    """Per impact what identification must obey: the operator's verdict, a clipped record's rejection, or
    None (the checks decide again)."""
    out: list[bool | None] = []
    for r in records:
        if r.verdict.forced is not None:
            out.append(r.verdict.forced)
        elif r.info.clipped and not r.accepted:
            out.append(False)  # the DAQ said so; the checks cannot see it in the samples
        else:
            out.append(None)
    return out


def process_step(records: Sequence[ImpactRecord], rig: RigConfig, checks: CheckConfig) -> StepResult:
    """Identify one load step from all its stored impacts, honouring every stored verdict."""
    records = list(records)
    if not records:
        return failed_step("no impacts stored")
    data = stack_impacts(records)
    try:
        ident = identify(data.force_n, data.accel_m_per_s2, data.sample_rate_hz, data.channels, rig,
                         accel_ranges=data.accel_ranges, force_range_n=data.force_range_n, config=checks,
                         forced=forced_verdicts(records))
    except ProcessingError as exc:
        return failed_step(str(exc), [ImpactOutcome(r.attempt, False, r.info.reasons) for r in records])
    return result_of(ident, data.attempts)


def result_of(ident: Identification, attempts: Sequence[int]) -> StepResult:
    """The stored result of a processing ``Identification`` whose impact ``i`` is stored as ``attempts[i]``.

    Every field is named once, here: a renamed or misspelt attribute raises instead of leaving a default.
    """
    i, p, pt = ident, plain, plain_tuple
    modes = tuple(ModeResult(m.kind, float(m.frequency_hz), float(m.frequency_std_hz), float(m.damping_ratio),
                             float(m.damping_ratio_std), float(m.coherence), float(m.bounce_mac),
                             float(m.tilt_fraction)) for m in i.modes)
    impacts = tuple(ImpactOutcome(int(attempts[c.index]), bool(c.accepted), tuple(c.reasons)) for c in i.impacts)
    return StepResult(
        bounce_hz=p(i.bounce_hz), bounce_hz_std=p(i.bounce_hz_std), bounce_damping_ratio=p(i.bounce_damping_ratio),
        bounce_damping_ratio_std=p(i.bounce_damping_ratio_std), tilt_hz=pt(i.tilt_hz), tilt_hz_std=pt(i.tilt_hz_std),
        tilt_pair_resolved=p(i.tilt_pair_resolved), roller_stiffness_n_per_m=p(i.roller_stiffness_n_per_m),
        roller_stiffness_std_n_per_m=p(i.roller_stiffness_std_n_per_m),
        roller_only_stiffness_n_per_m=p(i.roller_only_stiffness_n_per_m),
        roller_only_stiffness_std_n_per_m=p(i.roller_only_stiffness_std_n_per_m),
        roller_stiffness_budget_n_per_m=i.roller_stiffness_budget_n_per_m,
        roller_stiffnesses_n_per_m=pt(i.roller_stiffnesses_n_per_m),
        roller_stiffnesses_std_n_per_m=pt(i.roller_stiffnesses_std_n_per_m),
        roller_stiffnesses_resolved=p(i.roller_stiffnesses_resolved),
        roller_stiffness_condition=p(i.roller_stiffness_condition), rollers_differing=pt(i.rollers_differing),
        linearity=i.linearity, small_blow=i.small_blow, coherence_at_bounce=p(i.coherence_at_bounce),
        channels=pt(i.channels), dead_channels=pt(i.dead_channels), dropped_channels=pt(i.dropped_channels),
        classified_by_shape=p(i.classified_by_shape), fs_hz=p(i.fs_hz),
        window_decay_rate_per_s=p(i.window_decay_rate_per_s), fit_band_hz=pt(i.fit_band_hz), modes=modes,
        impacts=impacts, warnings=pt(i.warnings),
        frf=StepFrf(np.asarray(i.frequencies_hz), np.asarray(i.h1), np.asarray(i.coherence)))
