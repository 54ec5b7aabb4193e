"""The backend factory: maps ``--backend`` names to a ``drivers.Rig`` so the engine never imports a backend.

``sim`` builds the digital twin from physics objects (the rig file, the world's contact law for the mounted
contact case, ``rig_modes``); ``hw`` hands over to ``labctl.hardware`` (imported only when asked for).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from drivers.interfaces import Operator, Rig
from drivers.sim import FaultSettings, RigTwin, SimSettings, build_sim_rig
from drivers.sim.displacement import SimDisplacementSensor
from labctl.errors import InputError
from labctl.physics.contact import swing_stiffness_n_per_m
from labctl.physics.effects import ContactCase
from labctl.physics.rig import rig_modes, roller_path_stiffness
from labctl.physics.rig_config import RigConfig, load_rig
from labctl.physics.world import World, load_world

BACKENDS = ("sim", "hw")


def make_rig(
    backend: str = "sim",
    *,
    case: ContactCase,
    rig: RigConfig | str | Path | None = None,
    world: str | Path | None = None,
    seed: int | None = None,
    operator: Operator | None = None,
    devices: str | Path | None = None,
) -> Rig:
    """The instruments of a test stand: the simulated rig with ``case`` mounted, or the real hardware."""
    if backend == "hw":
        return _hardware(devices, operator)
    if backend != "sim":
        raise InputError(f"unknown backend {backend!r}; valid backends: {', '.join(BACKENDS)}")
    config = rig if isinstance(rig, RigConfig) else load_rig(rig)
    w = load_world(world)
    twin = make_twin(w, case, config, seed=seed)
    description = {
        "world": w.source,
        "world_description": w.description,
        "hidden_effects": ",".join(w.effect_names) or "none",
        "rig": config.source,
        "specimen": _specimen(case),
        "rail_ra_um": f"{case.rail_ra_m * 1e6:g}",
    }
    built = build_sim_rig(twin, operator, description)
    built.displacement = SimDisplacementSensor(twin, roller_path_stiffness)  # read only by static protocols
    return built


def make_twin(world: World, case: ContactCase, rig: RigConfig, *, seed: int | None = None) -> RigTwin:
    """The digital twin of ``rig`` (as it truly is in ``world``) with the rollers of ``case`` seated."""
    return RigTwin(world.true_rig(rig), world.specimen(case), rig_modes, swing_stiffness=swing_stiffness_n_per_m,
                   seed=seed,
                   settings=sim_settings(world), faults=fault_settings(world))


def sim_settings(world: World) -> SimSettings:
    """The simulator's instrument settings with the world file's ``[instruments]`` overrides."""
    fields = {f.name: f for f in dataclasses.fields(SimSettings)}
    unknown = sorted(set(world.instruments) - set(fields))
    if unknown:
        raise InputError(
            f"{world.source}: instruments: unknown setting(s) {', '.join(unknown)}; expected {', '.join(fields)}"
        )
    values = {k: int(v) if fields[k].type in (int, "int") else v for k, v in world.instruments.items()}
    try:
        return SimSettings(**values)
    except ValueError as exc:
        raise InputError(f"{world.source}: instruments: {exc}") from None


def fault_settings(world: World) -> FaultSettings:
    """The simulator's fault rates and sizes from the world file's ``[faults]`` table (none by default)."""
    names = [f.name for f in dataclasses.fields(FaultSettings)]
    unknown = sorted(set(world.faults) - set(names))
    if unknown:
        raise InputError(
            f"{world.source}: faults: unknown setting(s) {', '.join(unknown)}; expected {', '.join(names)}"
        )
    try:
        return FaultSettings(**world.faults)
    except ValueError as exc:
        raise InputError(f"{world.source}: faults: {exc}") from None


def _specimen(case: ContactCase) -> str:
    r = case.roller
    if r.type_id is not None:
        return f"roller type {r.type_id}"
    return f"D {r.diameter_m * 1e3:g} mm, L_we {r.contact_length_m * 1e3:g} mm, {r.material.name}"


def _hardware(devices: str | Path | None, operator: Operator | None) -> Rig:
    try:
        from labctl.hardware import make_hw_rig
    except ImportError as exc:
        raise InputError(f"hardware backend not available: {exc}") from None
    return make_hw_rig(devices, operator=operator)
