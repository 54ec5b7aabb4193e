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


STEPPED = """
[protocol]
name = "{name}"
[specimen]
roller_type = {roller_type}
rail_ra_um = 0.2
max_load_n = {max_load}
knob_step_deg = 90.0
[acquisition]
samples = 8192
impacts_per_step = 2
timeout_s = 5.0
[loading]
settle_poll_s = 0.0
settle_timeout_s = 5.0
max_steps = {max_steps}
[repetitions]
count = {reps}
"""


def stepped_protocol_text(name: str, roller_type: int, max_load: float, max_steps: int, reps: int) -> str:
    """TOML of a short roller protocol on Ra 0.2 µm rails: 90° knob steps, at most ``max_steps`` load steps of
    two 8192-sample impacts (the adaptive-campaign tests and bench)."""
    return STEPPED.format(name=name, roller_type=roller_type, max_load=max_load, max_steps=max_steps, reps=reps)


class Recorder:
    """Collects every event; ``of(T)`` filters by type."""

    def __init__(self) -> None:
        self.events: list[ev.Event] = []

    def __call__(self, event: ev.Event) -> None:
        self.events.append(event)

    def of(self, kind: type) -> list:
        return [e for e in self.events if isinstance(e, kind)]


def run_engine(path, protocol, factory, rig_config=None):
    """Run the engine directly (custom rig factory or rig model) into a new file; returns (outcome, recorder)."""
    from labctl.engine import Engine
    from labctl.physics import load_rig
    from labctl.storage import CampaignWriter

    writer = CampaignWriter.create(path, protocol_name=protocol.name, backend="sim", seed=None,
                                   config_files={"protocol.toml": protocol.source_text}, description={})
    rec = Recorder()
    bus = ev.EventBus()
    bus.subscribe(rec)
    try:
        outcome = Engine(protocol, rig_config or load_rig(), factory, writer, bus).run()
    finally:
        writer.close()
    return outcome, rec


def short_campaign_file(out, seed: int = 5, reps: int = 2):  # noqa: ANN001, ANN201 - path in, path out
    """A complete small campaign on the simulated rig (16 384-sample records, 2 impacts per step)."""
    from labctl.campaign import run_campaign

    outcome = run_campaign(short_protocol(max_load=120.0, samples=16384, impacts=2, reps=reps), out=out,
                           backend="sim", seed=seed)
    assert outcome.status == "complete", outcome.message
    return out
