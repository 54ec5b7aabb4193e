"""The static step of the paper's §2.5 method: paired load-cell and displacement readings at each load step,
stored with the step; after each repetition its static stiffness curve is stored with the run.

The step runner calls ``static_reading`` once, when it creates a step (so a resumed step keeps its reading),
and the sequencer calls ``store_static_curve`` after each repetition. Both talk to the engine through the
step runner's ``Services``.
"""

from __future__ import annotations

import json
from contextlib import ExitStack
from dataclasses import asdict
from typing import TYPE_CHECKING, Any

import numpy as np

from drivers.interfaces import Rig
from labctl import events as ev
from labctl.errors import LabctlError
from labctl.processing.static import StaticPoint, StaticStiffness, static_stiffness

if TYPE_CHECKING:  # the step runner calls this module
    from labctl.engine.steps import Services, StepRunner

PREFIX = "static_"
RUN_ATTR = "static_curve"
"""Run attribute: JSON list of the repetition's static stiffness points (``StaticStiffness`` fields)."""


def open_sensor(services: Services, rig: Rig, stack: ExitStack) -> None:
    """Open the rig's displacement sensor for a protocol with a ``[static]`` table (a clear error without one)."""
    if services.protocol.static is None:
        return
    if rig.displacement is None:
        raise LabctlError(f"protocol {services.protocol.name!r} asks for the static method but the "
                          f"{rig.backend} rig has no displacement sensor (devices file: [displacement])")
    services.call("displacement sensor (open)", rig.displacement.__enter__)
    stack.callback(rig.displacement.__exit__, None, None, None)


def static_reading(runner: StepRunner, pos: ev.Position) -> dict[str, Any]:
    """Read the load cell and the displacement sensor in turn ``reads`` times; the step attributes to store
    (means, read-to-read standard deviations, the rig-clock time), or nothing for a hammer-only protocol."""
    e, rig = runner.e, runner.rig
    spec = e.protocol.static
    if spec is None:
        return {}
    assert rig.displacement is not None
    loads, disps, times = [], [], []
    for _ in range(spec.reads):
        load, _stable = runner.read_load_once(pos)
        loads.append(load)
        times.append(rig.clock.now())
        disps.append(float(e.call("displacement sensor", rig.displacement.read)))  # type: ignore[arg-type]
    return {f"{PREFIX}load_n": float(np.mean(loads)), f"{PREFIX}load_sd_n": float(np.std(loads, ddof=1)),
            f"{PREFIX}displacement_m": float(np.mean(disps)),
            f"{PREFIX}displacement_sd_m": float(np.std(disps, ddof=1)),
            f"{PREFIX}reads": spec.reads, f"{PREFIX}time_s": float(np.mean(times))}


def point_of(step: int, attrs: dict[str, Any]) -> StaticPoint | None:
    """A step's stored static reading (None when the step has none)."""
    if f"{PREFIX}displacement_m" not in attrs:
        return None
    return StaticPoint(step, float(attrs[f"{PREFIX}load_n"]), float(attrs[f"{PREFIX}load_sd_n"]),
                       float(attrs[f"{PREFIX}displacement_m"]), float(attrs[f"{PREFIX}displacement_sd_m"]),
                       int(attrs[f"{PREFIX}reads"]), float(attrs[f"{PREFIX}time_s"]))


def store_static_curve(services: Services, series: int, run: int, steps: int) -> list[StaticStiffness]:
    """Compute and store the repetition's static stiffness curve from its steps' readings (a warning, and
    nothing stored, when the readings give no slope)."""
    e = services
    spec = e.protocol.static
    if spec is None:
        return []
    store = e.store
    points = [p for n in range(1, steps + 1) if (p := point_of(n, store.step_attrs(series, run, n))) is not None]
    u = e.rig_config.uncertainty
    try:
        curve = static_stiffness(points, e.rig_config.setup_stiffness_n_per_m, u.setup_stiffness_std_n_per_m,
                                 spec.drift_m_per_s)
    except LabctlError as exc:
        e.notify("warning", f"no static stiffness for this repetition: {exc}", position=ev.Position(series, run))
        return []
    store.set_run_attrs(series, run, {RUN_ATTR: json.dumps([asdict(c) for c in curve])})
    return curve


def stored_static_curve(run_attrs: dict[str, Any]) -> list[StaticStiffness]:
    """A repetition's stored static curve (empty when it has none)."""
    raw = run_attrs.get(RUN_ATTR)
    if raw is None:
        return []
    return [StaticStiffness(**c) for c in (json.loads(raw) if isinstance(raw, str) else raw)]
