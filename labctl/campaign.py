"""The Python API for scripts: run, resume and process campaigns with the same code the CLI and TUI use.

    from labctl.campaign import run_campaign
    outcome = run_campaign("protocols/quick_check.toml", out="qc.h5", backend="sim", seed=1)
    for curve in outcome.curves: print(curve.load_n, curve.stiffness_n_per_m)
"""

from __future__ import annotations

import json
import tomllib
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from drivers.interfaces import REVIEW_CHOICES, Operator, Rig
from drivers.operators import ScriptedOperator
from labctl.backends import make_rig
from labctl.engine import Condition, Engine, Outcome, RunControl
from labctl.engine.control import stop_on_hangup
from labctl.engine.plan import plan_steps
from labctl.errors import InputError
from labctl.events import Event, EventBus
from labctl.physics.rig_config import RigConfig, load_rig
from labctl.physics.world import load_world, world_path
from labctl.protocol import Protocol, SpecimenSpec, load_protocol
from labctl.storage import CampaignWriter

REVIEW_KEYS = {"series": 1, "run": 1, "step": None, "attempt": None, "verdict": None, "reason": None}


def load_operator_script(path: str | Path) -> ScriptedOperator:
    """A scripted operator from a TOML file: verdicts on chosen blows (``[[review]]`` tables) and answers to
    prompts by action (``[answers]``: action = [answers in order]); every other prompt gets its first choice.
    """
    p = Path(path)
    try:
        doc = tomllib.loads(p.read_text(encoding="utf-8-sig"))  # a byte-order mark is not content
    except FileNotFoundError:
        raise InputError(f"{p}: operator script not found") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise InputError(f"{p}: not a readable TOML operator script ({exc})") from None
    unknown = sorted(set(doc) - {"review", "answers"})
    if unknown:
        raise InputError(f"{p}: unknown table {unknown[0]!r}; expected [[review]] and [answers]")
    answers = doc.get("answers", {})
    if not isinstance(answers, dict) or not all(isinstance(v, list) and all(isinstance(a, str) for a in v)
                                                for v in answers.values()):
        raise InputError(f"{p}: [answers]: expected action = [\"answer\", ...] lists of strings")
    reviews: dict[tuple[int, int, int, int], tuple[str, str]] = {}
    entries = doc.get("review", [])
    if not isinstance(entries, list):
        raise InputError(f"{p}: review: expected [[review]] tables")
    for n, entry in enumerate(entries, start=1):
        key, verdict, reason = _review_entry(entry, f"{p}: [[review]] #{n}")
        if key in reviews:
            raise InputError(f"{p}: [[review]] #{n}: series {key[0]} run {key[1]} step {key[2]} attempt {key[3]} "
                             "has a verdict already")
        reviews[key] = (verdict, reason)
    return ScriptedOperator(answers={k: list(v) for k, v in answers.items()}, reviews=reviews,
                            name=f"operator@{p.name}")


def _review_entry(entry: Any, where: str) -> tuple[tuple[int, int, int, int], str, str]:
    if not isinstance(entry, dict):
        raise InputError(f"{where}: expected a table")
    unknown = sorted(set(entry) - set(REVIEW_KEYS))
    if unknown:
        raise InputError(f"{where}: unknown key {unknown[0]!r}; expected {', '.join(REVIEW_KEYS)}")
    values = {k: entry.get(k, default) for k, default in REVIEW_KEYS.items()}
    for k in ("series", "run", "step", "attempt"):
        v = values[k]
        if v is None:
            raise InputError(f"{where}: {k} is missing; expected an integer >= 1")
        if not isinstance(v, int) or isinstance(v, bool) or v < 1:
            raise InputError(f"{where}: {k} = {v!r}; expected an integer >= 1")
    if values["verdict"] not in REVIEW_CHOICES:
        raise InputError(f"{where}: verdict = {values['verdict']!r}; expected one of {', '.join(REVIEW_CHOICES)}")
    reason = values["reason"]
    if not isinstance(reason, str) or not reason.strip():
        raise InputError(f"{where}: reason = {reason!r}; expected a non-empty text saying why")
    key = (values["series"], values["run"], values["step"], values["attempt"])
    return key, str(values["verdict"]), reason.strip()


def _check_reviews(operator: Operator | None, proto: Protocol, rig_config: RigConfig, added_steps: int) -> None:
    """Every scripted verdict must name an impact the protocol can take (else it would silently never apply):
    a series and repetition it has, a step within its plan (with an adaptive campaign's added steps: the steps a
    repetition may run past the plan when its loads run clearly under the cap are not planned, so a verdict for
    one is refused rather than left unused), an attempt within the impacts and re-hits of a step."""
    from labctl.engine.plan import EXTRA_STEPS

    reviews = getattr(operator, "reviews", None)
    if not reviews:
        return
    acq = proto.acquisition
    attempts = acq.impacts_per_step + acq.max_rehits + 1
    for series, run, step, attempt in sorted(reviews):
        where = f"{getattr(operator, 'name', 'operator')}: [[review]] series {series} run {run} step {step} " \
                f"attempt {attempt}"
        if series > len(proto.specimens):
            raise InputError(f"{where}: the protocol has {len(proto.specimens)} specimen series; this verdict "
                             "would never apply")
        if run > proto.repetitions.count:
            raise InputError(f"{where}: the protocol has {proto.repetitions.count} repetition(s); this verdict "
                             "would never apply")
        planned = plan_steps(proto, proto.specimens[series - 1], rig_config).steps_estimate
        if step > planned + added_steps:  # past the plan only when the loads run clearly under the rig's calibration
            extra = f" and up to {added_steps} the planner adds" if added_steps else ""
            raise InputError(f"{where}: series {series} plans {planned} load steps{extra} (at most {EXTRA_STEPS} "
                             "more only if the measured loads run clearly below the rig's load per knob degree); "
                             "this verdict would never apply")
        if attempt > attempts:
            raise InputError(f"{where}: a step takes at most {attempts} impacts ({acq.impacts_per_step} and "
                             f"{acq.max_rehits} re-hits); this verdict would never apply")


def _text(path: str | Path | None) -> str:
    return "" if path is None else Path(path).read_text(encoding="utf-8")


def _config_files(protocol: Protocol, rig: RigConfig, world: str | Path | None,
                  devices: str | Path | None) -> dict[str, str]:
    files = {"protocol.toml": protocol.source_text, "rig.toml": _text(rig.source)}
    if world is not None:
        files["world.toml"] = _text(world_path(world))
    if devices is not None:
        files["devices.toml"] = _text(devices)
    return files


def rig_factory(backend: str, rig: RigConfig, *, world: str | Path | None = None, seed: int | None = None,
                operator: Operator | None = None, devices: str | Path | None = None
                ) -> Callable[[SpecimenSpec, int], Rig]:
    """Instruments per specimen series; the simulated rig gets the specimen mounted and a seed per series."""

    def make(spec: SpecimenSpec, series: int) -> Rig:
        world_file = world
        if backend == "sim" and world is None and spec.kind == "ball":
            world_file = "balls"
        s = None if seed is None else seed * 1000 + series
        return make_rig(backend, case=spec.case(), rig=rig, world=world_file, seed=s, operator=operator,
                        devices=devices)

    return make


def _check_world_loads(sim_world: Any, proto: Protocol, rig_config: RigConfig, world: str | Path | None) -> None:
    """A world law must give every roller specimen a usable stiffness over the loads the protocol will set
    (preload to cap), checked before a file is made: a law failing at step 2 is a bad world file, not a run."""
    import numpy as np

    from labctl.physics.world_laws import WorldLaw

    if not isinstance(sim_world.law, WorldLaw):
        return
    for spec in proto.specimens:
        if spec.kind != "roller":
            continue
        loads = np.linspace(rig_config.preload_per_roller_n, spec.max_load_n, 16)
        try:
            sim_world.law.stiffness_n_per_m(spec.case(), loads)
        except ValueError as exc:
            raise InputError(f"{world}: {exc}") from None


@dataclass(frozen=True)
class CampaignRequest:
    """What a campaign run was asked for, with a resumed file's stored settings taking precedence."""

    protocol: Protocol
    out: Path
    backend: str = "sim"
    world: str | Path | None = None
    seed: int | None = None
    rig: str | Path | None = None
    devices: str | Path | None = None
    budget_steps: int = 0
    """Load steps an adaptive campaign may add per repetition (0: not adaptive)."""


def run_campaign(protocol: str | Path | Protocol, *, out: str | Path, backend: str = "sim", resume: bool = False,
                 world: str | Path | None = None, seed: int | None = None, rig: str | Path | None = None,
                 devices: str | Path | None = None, operator: Operator | None = None,
                 subscribers: Iterable[Callable[[Event], object]] = (), control: RunControl | None = None,
                 conditions: Sequence[Condition] = (), adaptive: bool = False,
                 budget_steps: int | None = None) -> Outcome:
    """Run a protocol (or continue an interrupted campaign with ``resume=True``) and return how it ended.

    ``adaptive``: after each repetition's base steps, add up to ``budget_steps`` (default
    ``DEFAULT_BUDGET_STEPS``) load steps the planner ranks highest for the mounted specimen (docs/planning.md).
    A resumed campaign keeps the adaptive setting and budget it was started with.

    Every input (protocol, rig, world, devices, output path) is read and checked before a new file is
    created, so a bad input leaves no file behind. ``conditions`` are extra safe-point checks for the engine.
    """
    out = Path(out)
    control = control if control is not None else RunControl()
    with stop_on_hangup(control):  # before the file exists: a SIGTERM in set-up stops the run at its first impact
        writer = CampaignWriter.open_existing(out) if resume else None
        created = False
        try:
            proto = protocol if isinstance(protocol, Protocol) else load_protocol(protocol)
            asked = CampaignRequest(proto, out, backend, world, seed, rig, devices)
            request = _continued(asked, writer) if writer is not None else _fresh(asked, adaptive, budget_steps)
            rig_config, devices = _checked_inputs(request)
            _check_reviews(operator, proto, rig_config, request.budget_steps)
            if writer is None:
                writer, created = _create_file(request, rig_config, devices), True
            engine = _engine(request, rig_config, devices, writer, operator, subscribers, control, conditions)
        except BaseException:
            if writer is not None:
                writer.close()
            if created:
                out.unlink(missing_ok=True)  # nothing was measured: leave no stub behind
            raise
        try:
            return engine.run()
        finally:
            writer.close()


def _continued(asked: CampaignRequest, writer: CampaignWriter) -> CampaignRequest:
    """The request for resuming ``writer``'s campaign: its stored backend, seed, world and adaptive budget."""
    stored = writer.config_text("protocol.toml")
    if stored is not None and stored != asked.protocol.source_text:
        raise InputError(f"{asked.out}: was written with a different protocol than {asked.protocol.source_path}; "
                         "resume with the same protocol file")
    attrs = writer.attrs
    desc = attrs.get("backend_description") or {}
    desc = desc if isinstance(desc, dict) else json.loads(str(desc) or "{}")
    seed_attr = int(attrs.get("seed", -1))
    return replace(asked, backend=str(attrs.get("backend", asked.backend)),
                   seed=asked.seed if asked.seed is not None else (None if seed_attr < 0 else seed_attr),
                   world=asked.world if asked.world is not None else desc.get("world_file") or None,
                   budget_steps=int(desc.get("adaptive_budget_steps", 0) or 0))


def _fresh(asked: CampaignRequest, adaptive: bool, budget_steps: int | None) -> CampaignRequest:
    """The request for a new campaign file (refused where a file, or a file for its folder, already is)."""
    out = asked.out
    if out.exists():
        raise InputError(f"{out}: already exists; use --resume to continue it or choose another --out")
    if out.parent.exists() and not out.parent.is_dir():
        raise InputError(f"{out}: its folder {out.parent} is a file")
    if not adaptive:
        return asked
    if budget_steps is None:
        from labctl.planning.plan import DEFAULT_BUDGET_STEPS

        budget_steps = DEFAULT_BUDGET_STEPS
    if budget_steps < 1:
        raise InputError(f"--budget-steps {budget_steps}: expected at least 1 load step")
    return replace(asked, budget_steps=budget_steps)


def _checked_inputs(request: CampaignRequest) -> tuple[RigConfig, str | Path | None]:
    """Read and check every input before anything is written: the rig, each specimen's plan, the world (sim,
    its law usable over the protocol's loads) or the devices file (hw, returned as found)."""
    proto, devices = request.protocol, request.devices
    rig_config = load_rig(request.rig)
    if request.budget_steps:
        for spec in proto.specimens:
            if spec.kind != "roller":
                raise InputError(f"{proto.source_path}: specimen {spec.label!r} is a {spec.kind}; "
                                 "--adaptive plans roller specimens only")
    for spec in proto.specimens:
        spec.case()
        plan_steps(proto, spec, rig_config)
    if request.backend == "sim":
        sim_world = load_world(request.world)
        if any(spec.kind == "ball" for spec in proto.specimens) and request.world is None:
            load_world("balls")
        _check_world_loads(sim_world, proto, rig_config, request.world)
    if request.backend == "hw":
        from labctl.hardware import find_devices_file, load_devices, rig_with_channel_cross_axis

        devices = find_devices_file(devices)
        if load_devices(devices)["load_cell"].kind == "none" and proto.loading.load_source != "springs":
            raise InputError(f"{devices}: no [load_cell]: a rig without one runs only protocols with [loading] "
                             f"load_source = \"springs\" ({proto.source_path} reads a load cell)")
        rig_config = rig_with_channel_cross_axis(rig_config, _text(devices), str(devices))
    return rig_config, devices


def _create_file(request: CampaignRequest, rig_config: RigConfig, devices: str | Path | None) -> CampaignWriter:
    """The new campaign file with the configuration it runs on."""
    world = request.world
    return CampaignWriter.create(request.out, protocol_name=request.protocol.name, backend=request.backend,
                                 seed=request.seed,
                                 config_files=_config_files(request.protocol, rig_config, world, devices),
                                 description={"world_file": "" if world is None else str(world),
                                              "rig_file": rig_config.source,
                                              "adaptive_budget_steps": request.budget_steps})


def _engine(request: CampaignRequest, rig_config: RigConfig, devices: str | Path | None, writer: CampaignWriter,
            operator: Operator | None, subscribers: Iterable[Callable[[Event], object]], control: RunControl | None,
            conditions: Sequence[Condition]) -> Engine:
    """The engine for a request, writing to ``writer``, with the planner as advisor when adaptive."""
    factory = rig_factory(request.backend, rig_config, world=request.world, seed=request.seed, operator=operator,
                          devices=devices)
    bus = EventBus()
    for sub in subscribers:
        bus.subscribe(sub)
    advisor = None
    if request.budget_steps:
        from labctl.planning.adaptive import PlanAdvisor

        advisor = PlanAdvisor(rig_config)
    return Engine(request.protocol, rig_config, factory, writer, bus, control, conditions, advisor=advisor,
                  budget_steps=request.budget_steps)
