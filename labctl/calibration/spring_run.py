"""The spring characterisation run: knob angle against load-cell load, loading and unloading, and its file.

The protocol (``protocols/spring_characterisation.toml``, a ``[characterisation]`` table) names the knob
step, the largest angle and the number of load–unload cycles. The run reads the preload before any turn, then
turns all knobs together step by step up to the largest angle and back to zero, reading the load cell (stable)
at every step, and has the rollers re-seated between cycles (as a campaign does between repetitions, so the
slack the nuts take up anew shows in the curve's scatter). It runs on any ``Rig`` (the twin or hardware)
through the same instrument calls.
The readings go to a small HDF5 file (``kind = "spring_characterisation"``) with the protocol and rig text.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from drivers.interfaces import Rig
from labctl.calibration.springs import SpringData
from labctl.data.schema import Flag, Integer, Number, Spec, Table, Text, Where, check_keys, parse_toml, read, value
from labctl.errors import InputError
from labctl.storage.springs import read_spring_file, write_spring_file

HEAD: dict[str, Spec] = {"name": Text(default="spring_characterisation"), "description": Text(default=""),
                         "version": Integer(default=1)}
CHARACTERISATION: dict[str, Spec] = {
    "knob_step_deg": Number(gt=0, le=3600), "max_angle_deg": Number(gt=0, le=36000),
    "cycles": Integer(1, 20, default=3), "zero_reads": Integer(2, 100, default=5),
    "reseat_between_cycles": Flag(default=True),
    "settle_timeout_s": Number(gt=0, default=30.0), "settle_poll_s": Number(ge=0, default=0.1),
}


@dataclass(frozen=True)
class SpringProtocol:
    """What a characterisation run does; ``source_text`` is stored verbatim in its file."""

    name: str
    description: str
    knob_step_deg: float
    max_angle_deg: float
    cycles: int
    zero_reads: int
    settle_timeout_s: float
    settle_poll_s: float
    reseat: bool = True
    source_text: str = ""

    def angles_deg(self) -> list[float]:
        """One cycle's knob angles: up from the first step to the largest angle, then back down to zero."""
        n = int(np.floor(self.max_angle_deg / self.knob_step_deg + 1e-9))
        up = [self.knob_step_deg * i for i in range(1, n + 1)]
        return up + up[-2::-1] + [0.0]


def parse_spring_protocol(text: str, path: str = "<protocol>") -> SpringProtocol:
    """Validate a spring characterisation protocol; errors name the file, table and key."""
    doc = parse_toml(text, path)
    top = Where(path)
    check_keys(doc, {"protocol", "characterisation"}, top)
    head = read(value(doc, "protocol", Table(default={}), top), HEAD, top.at("protocol"))
    c = read(value(doc, "characterisation", Table(), top), CHARACTERISATION, top.at("characterisation"))
    if c["knob_step_deg"] > c["max_angle_deg"]:
        raise top.at("characterisation").bad("knob_step_deg", c["knob_step_deg"],
                                              f"at most max_angle_deg = {c['max_angle_deg']:g}")
    return SpringProtocol(head["name"], head["description"], c["knob_step_deg"], c["max_angle_deg"], c["cycles"],
                          c["zero_reads"], c["settle_timeout_s"], c["settle_poll_s"], c["reseat_between_cycles"],
                          text)


def load_spring_protocol(path: str | Path) -> SpringProtocol:
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: spring characterisation protocol not found")
    return parse_spring_protocol(p.read_text(encoding="utf-8"), str(p))


def _read_stable(rig: Rig, proto: SpringProtocol, rollers: int) -> float:
    deadline = rig.clock.now() + proto.settle_timeout_s
    while True:
        reading = rig.load_cell.read()
        if reading.stable or rig.clock.now() >= deadline:
            return reading.force_n / rollers
        rig.clock.sleep(proto.settle_poll_s)


def characterise(rig: Rig, proto: SpringProtocol, rollers: int, source: str = "") -> SpringData:
    """Run the protocol on ``rig`` (knobs at zero to start): knob angle vs load per roller, both directions."""
    if abs(rig.actuator.knob_angle_deg) > 1e-9:
        raise InputError(f"the knobs stand at {rig.actuator.knob_angle_deg:g}°: unload to 0° before characterising")
    angles, loads, dirs = [], [], []
    for _ in range(proto.zero_reads):
        angles.append(0.0)
        loads.append(_read_stable(rig, proto, rollers))
        dirs.append(1)
    for cycle in range(proto.cycles):
        if cycle and proto.reseat:  # the slack a campaign meets after each re-seating belongs in the scatter
            rig.operator.prompt("lift the upper disc, turn the rollers, lower it and run the knob nuts back on",
                                ("ok",), "rotate_rollers")
        previous = 0.0
        for angle in proto.angles_deg():
            rig.actuator.turn_knobs(angle - rig.actuator.knob_angle_deg)
            angles.append(angle)
            loads.append(_read_stable(rig, proto, rollers))
            dirs.append(1 if angle > previous else -1)
            previous = angle
    return SpringData(np.array(angles), np.array(loads), np.array(dirs, dtype=int), source)


def write_characterisation(path: str | Path, data: SpringData, proto: SpringProtocol, rig_text: str,
                           description: dict[str, Any]) -> None:
    """Store a characterisation's readings with its protocol and rig text; never overwrites an existing file."""
    write_spring_file(path, {"angle_deg": data.angle_deg, "load_n": data.load_n, "direction": data.direction},
                      {"protocol_text": proto.source_text, "rig_text": rig_text, "backend": json.dumps(description)})


def read_characterisation(path: str | Path) -> tuple[SpringData, str]:
    """The readings of a characterisation file and the rig text stored with them."""
    arrays, attrs = read_spring_file(path)
    return SpringData(arrays["angle_deg"], arrays["load_n"], arrays["direction"], str(path)), attrs["rig_text"]
