"""Small helpers for engine tests: short protocols and event recorders."""

from __future__ import annotations

from labctl import events as ev
from labctl.protocol import parse_protocol

SHORT = """
[protocol]
name = "short"
[specimen]
roller_type = 1
rail_ra_um = 0.2
max_load_n = {max_load}
knob_step_deg = {step}
[acquisition]
samples = {samples}
impacts_per_step = {impacts}
timeout_s = 5.0
[loading]
settle_poll_s = 0.0
settle_timeout_s = 5.0
[repetitions]
count = {reps}
"""


def short_protocol(max_load: float = 120.0, step: float = 360.0, samples: int = 16384, impacts: int = 2,
                   reps: int = 2):
    return parse_protocol(SHORT.format(max_load=max_load, step=step, samples=samples, impacts=impacts, reps=reps),
                          "short.toml")


class Recorder:
    """Collects every event; ``of(T)`` filters by type."""

    def __init__(self) -> None:
        self.events: list[ev.Event] = []

    def __call__(self, event: ev.Event) -> None:
        self.events.append(event)

    def of(self, kind: type) -> list:
        return [e for e in self.events if isinstance(e, kind)]
