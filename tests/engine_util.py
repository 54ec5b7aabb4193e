"""Small helpers for engine tests: short protocols, event recorders, and a scripted rig with a scripted
identification that runs the engine's logic into a ``MemoryStore`` in milliseconds."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from drivers.errors import DeviceTimeout
from drivers.interfaces import Channel, LoadReading, Record, Rig, TriggerSpec
from drivers.operators import ScriptedOperator
from labctl import events as ev
from labctl.protocol import load_protocol, parse_protocol
from labctl.storage.memory import MemoryStore
from labctl.storage.records import ImpactOutcome, StepFrf, StepResult, failed_step

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


def quick_check_short(samples: int = 16384):  # noqa: ANN201 - a Protocol
    """The shipped quick_check, name and steps, with records of ``samples`` (0.8 s: the blow has died out) instead
    of 3.2 s: for tests of the flow (screens, dialogs, the gate), not of the numbers; a quarter of the twin's work
    per blow."""
    shipped = load_protocol("quick_check").source_text
    text = shipped.replace("samples = 65536", f"samples = {samples}")
    assert text != shipped, "quick_check.toml no longer says samples = 65536"
    return parse_protocol(text, "quick_check.toml")


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


def run_engine(path, protocol, factory, rig_config=None, **engine_kw):
    """Run the engine directly (custom rig factory or rig model, ``Engine`` keywords) into a new file; returns
    (outcome, recorder)."""
    from labctl.engine import Engine
    from labctl.physics import load_rig
    from labctl.storage import CampaignWriter

    writer = CampaignWriter.create(path, protocol_name=protocol.name, backend="sim", seed=None,
                                   config_files={"protocol.toml": protocol.source_text}, description={})
    rec = Recorder()
    bus = ev.EventBus()
    bus.subscribe(rec)
    try:
        outcome = Engine(protocol, rig_config or load_rig(), factory, writer, bus, **engine_kw).run()
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


# --- a scripted rig and a scripted identification: the engine's logic without the twin, HDF5 or processing ----
CHANNELS = tuple(f"A{i}{axis}" for i in range(1, 5) for axis in "XYZ")


def blow_record(fs_hz: float = 20480.0, n: int = 1024, peak_n: float = 800.0, double: bool = False,
                timestamp_s: float = 0.0) -> Record:
    """A 0.3 ms half-sine blow (a second one 30 % as strong 5 ms later when ``double``) and 12 ringing channels."""
    t = np.arange(n) / fs_hz
    force = np.zeros(n)
    for start, size in ((0.005, 1.0), (0.010, 0.3))[: 2 if double else 1]:
        on = (t >= start) & (t <= start + 3e-4)
        force[on] += size * peak_n * np.sin(np.pi * (t[on] - start) / 3e-4)
    ring = np.where(t >= 0.005, np.sin(2 * np.pi * 700.0 * (t - 0.005)) * np.exp(-40.0 * (t - 0.005)), 0.0)
    return Record(fs_hz, force, np.tile(ring, (len(CHANNELS), 1)), CHANNELS, int(0.005 * fs_hz), timestamp_s)


class VirtualClock:
    """Time that passes only when slept."""

    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        self.t += max(seconds, 0.0)


class _Part:
    def __init__(self, bench: ScriptedBench, name: str) -> None:
        self.bench, self.name = bench, name

    def open(self) -> None: ...
    def close(self) -> None: ...

    def __enter__(self) -> _Part:
        return self

    def __exit__(self, *exc: object) -> None: ...


class _Daq(_Part):
    channels = (Channel("F", "force", "N", 0.002, 5000.0),) + tuple(
        Channel(c, "acceleration", "m/s^2", 0.01, 500.0) for c in CHANNELS)

    def configure(self, sample_rate_hz: float, n_samples: int) -> float:
        self.bench.fs_hz = sample_rate_hz
        return sample_rate_hz

    def arm(self, trigger: TriggerSpec) -> None:
        self.bench.armed = True

    def acquire(self, timeout_s: float) -> Record:
        b = self.bench
        if not b.armed or b.pending is None:
            raise DeviceTimeout(self.name, "acquire", f"no blow within {timeout_s:g} s")
        record, b.pending, b.armed = b.pending, None, False
        return record


class _Hammer(_Part):
    def strike(self) -> None:
        b = self.bench
        b.blows += 1
        kind = b.blow_kind(b.blows)
        b.clock.sleep(0.5)
        b.pending = None if kind == "miss" else blow_record(b.fs_hz, double=kind == "double",
                                                            timestamp_s=1.7e9 + b.clock.now())
        b.after_strike(b)


class _LoadCell(_Part):
    def read(self) -> LoadReading:
        b = self.bench
        b.reads += 1
        return LoadReading(b.rig.roller_count * b.load_per_roller_n() + b.offset_n, b.reads > b.settle_reads)

    def tare(self) -> None: ...


class _Actuator(_Part):
    @property
    def knob_angle_deg(self) -> float:
        return self.bench.angle_deg

    def turn_knobs(self, angle_deg: float) -> None:
        self.bench.angle_deg += angle_deg
        self.bench.reads = 0


class ScriptedBench:
    """Scripted instruments sharing one state: the load follows the rig model exactly; ``blow_kind(n)`` says
    whether blow ``n`` is "clean", "double" (the checks reject it) or a "miss" (no trigger); ``after_strike``
    lets a test act after each blow (e.g. make the load drift by setting ``offset_n``)."""

    def __init__(self, rig_config: object, blow_kind: Callable[[int], str] = lambda n: "clean",
                 after_strike: Callable[[ScriptedBench], None] = lambda b: None, settle_reads: int = 1,
                 operator: object | None = None) -> None:
        self.rig, self.blow_kind, self.after_strike = rig_config, blow_kind, after_strike
        self.settle_reads = settle_reads
        self.operator = operator if operator is not None else ScriptedOperator()
        self.angle_deg, self.offset_n, self.reads, self.blows, self.fs_hz = 0.0, 0.0, 0, 0, 20480.0
        self.pending: Record | None = None
        self.armed = False
        self.clock = VirtualClock()

    def load_per_roller_n(self) -> float:
        return self.rig.preload_per_roller_n + self.angle_deg * self.rig.load_per_knob_degree_n

    def rig_factory(self, spec: object, series: int) -> Rig:
        return Rig(_Daq(self, "daq"), _Hammer(self, "hammer"), _LoadCell(self, "cell"), _Actuator(self, "actuator"),
                   self.operator, backend="scripted", clock=self.clock)


def scripted_identify(records, rig, checks) -> StepResult:  # noqa: ANN001 - the StepProcessor signature
    """A step result without processing: identified from the impacts whose stored verdict accepts them."""
    outcomes = tuple(ImpactOutcome(r.attempt, r.accepted, r.info.reasons) for r in records)
    used = [r for r in records if r.accepted]
    if not used:
        return failed_step(f"all {len(records)} impacts rejected", outcomes)
    f = np.linspace(0.0, 2000.0, 5)
    return StepResult(bounce_hz=700.0, tilt_hz=(900.0, 910.0), roller_stiffness_n_per_m=3.0e7 + 1e5 * len(used),
                      roller_stiffness_std_n_per_m=1e5, coherence_at_bounce=0.99, channels=CHANNELS,
                      impacts=outcomes, frf=StepFrf(f, np.ones((len(CHANNELS), f.size), complex),
                                                    np.ones((len(CHANNELS), f.size))))


def run_scripted(protocol, bench: ScriptedBench, store=None, control=None):  # noqa: ANN001, ANN201
    """Run the engine on a scripted bench into a ``MemoryStore`` (or ``store``); returns (outcome, recorder, store)."""
    from labctl.engine import Engine
    from labctl.physics import load_rig

    store = store if store is not None else MemoryStore()
    rec = Recorder()
    bus = ev.EventBus()
    bus.subscribe(rec)
    engine = Engine(protocol, load_rig(), bench.rig_factory, store, bus, control, identify_step=scripted_identify)
    return engine.run(), rec, store


def impact_event(position: ev.Position, attempt: int, reasons: tuple[str, ...] = (), force_n=None,  # noqa: ANN001
                 accel_m_per_s2=None, channels: tuple[str, ...] = ("A1Z", "A2Z"), peak_force_n: float = 200.0,
                 range_use: dict[str, float] | None = None, accepted: bool | None = None,
                 fs_hz: float = 20480.0) -> ev.ImpactAcquired:
    """An ImpactAcquired (ImpactRejected when not ``accepted``, by default when there are ``reasons``) carrying
    a small stored record, for display tests."""
    from labctl.storage.records import CheckSummary, ImpactInfo, ImpactRecord, Verdict

    force = np.zeros(8) if force_n is None else np.asarray(force_n, dtype=float)
    accel = np.zeros((len(channels), force.size)) if accel_m_per_s2 is None else np.asarray(accel_m_per_s2)
    ok = not reasons if accepted is None else accepted
    info = ImpactInfo(attempt, fs_hz, 0, "", CheckSummary(ok, reasons, peak_force_n, 4e-4), Verdict(ok), ())
    cls = ev.ImpactAcquired if ok else ev.ImpactRejected
    return cls(1.0, position, ImpactRecord(info, channels, force, accel), range_use or {})


def step_event(position: ev.Position, load_n: float, bounce_hz: float, tilt_hz: tuple[float, float], k: float,
               frequencies_hz, h1, coherence, channels: tuple[str, ...] = ("A1Z",),  # noqa: ANN001
               k_std: float = float("nan"), used: tuple[int, ...] = (), rejected: dict[int, str] | None = None,
               warnings: tuple[str, ...] = (), time_s: float = 1.0, coherence_at_bounce: float = 0.99
               ) -> ev.StepProcessed:
    """A StepProcessed carrying a step result with these values, for display tests."""
    outcomes = tuple(ImpactOutcome(a, True) for a in used) + tuple(
        ImpactOutcome(a, False, tuple(why.split(", "))) for a, why in (rejected or {}).items())
    result = StepResult(bounce_hz=bounce_hz, tilt_hz=tilt_hz, roller_stiffness_n_per_m=k,
                        roller_stiffness_std_n_per_m=k_std, coherence_at_bounce=coherence_at_bounce, channels=channels,
                        impacts=outcomes, warnings=warnings,
                        frf=StepFrf(np.asarray(frequencies_hz), np.asarray(h1, dtype=complex), np.asarray(coherence)))
    return ev.StepProcessed(time_s, position, load_n, result)
