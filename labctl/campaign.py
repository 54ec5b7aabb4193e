"""The Python API for scripts: run, resume and process campaigns with the same code the CLI and TUI use.

    from labctl.campaign import run_campaign
    outcome = run_campaign("protocols/quick_check.toml", out="qc.h5", backend="sim", seed=1)
    for curve in outcome.curves: print(curve["load_n"], curve["stiffness_n_per_m"])
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable
from pathlib import Path

from drivers.interfaces import Operator, Rig
from labctl.backends import make_rig
from labctl.engine import Engine, Outcome, RunControl
from labctl.errors import InputError
from labctl.events import Event, EventBus
from labctl.physics.rig_config import RigConfig, load_rig
from labctl.physics.world import load_world, world_path
from labctl.protocol import Protocol, SpecimenSpec, load_protocol
from labctl.storage import CampaignWriter


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


def run_campaign(protocol: str | Path | Protocol, *, out: str | Path, backend: str = "sim", resume: bool = False,
                 world: str | Path | None = None, seed: int | None = None, rig: str | Path | None = None,
                 devices: str | Path | None = None, operator: Operator | None = None,
                 subscribers: Iterable[Callable[[Event], object]] = (), control: RunControl | None = None
                 ) -> Outcome:
    """Run a protocol (or continue an interrupted campaign with ``resume=True``) and return how it ended."""
    out = Path(out)
    if resume:
        writer = CampaignWriter.open_existing(out)
        stored = writer.config_text("protocol.toml")
        proto = protocol if isinstance(protocol, Protocol) else load_protocol(protocol)
        if stored is not None and stored != proto.source_text:
            writer.close()
            raise InputError(f"{out}: was written with a different protocol than {proto.source_path}; "
                             "resume with the same protocol file")
        desc = json.loads(str(writer.h5.attrs.get("backend_description", "{}")) or "{}")
        backend = str(writer.h5.attrs.get("backend", backend))
        seed_attr = int(writer.h5.attrs.get("seed", -1))
        seed = seed if seed is not None else (None if seed_attr < 0 else seed_attr)
        world = world if world is not None else desc.get("world_file") or None
    else:
        proto = protocol if isinstance(protocol, Protocol) else load_protocol(protocol)
    rig_config = load_rig(rig)
    if backend == "hw" and devices is None:
        from labctl.hardware import find_devices_file

        devices = find_devices_file(None)
    if backend == "hw":  # a bad devices or world file is refused before any campaign file exists
        from labctl.hardware import load_devices

        load_devices(devices)
    elif backend == "sim":
        load_world(world)
    factory = rig_factory(backend, rig_config, world=world, seed=seed, operator=operator, devices=devices)
    if not resume:
        writer = CampaignWriter.create(out, protocol_name=proto.name, backend=backend, seed=seed,
                                       config_files=_config_files(proto, rig_config, world, devices),
                                       description={"world_file": "" if world is None else str(world),
                                                    "rig_file": rig_config.source})
    bus = EventBus()
    for sub in subscribers:
        bus.subscribe(sub)
    try:
        return Engine(proto, rig_config, factory, writer, bus, control).run()
    finally:
        writer.close()
