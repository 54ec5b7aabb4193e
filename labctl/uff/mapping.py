"""UFF58 conventions of docs/contracts.md: channel ↔ node and direction, function and ordinate codes, unit labels.

Nodes 1–3 are the accelerometers A1–A3 above the rollers, node 4 is A4 under the bottom disc, node 10 the
hammer; directions 1/2/3 are X/Y/Z. Other acquisition systems number their nodes their own way: a
:class:`NodeMap` says which node is which sensor.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from labctl.errors import InputError

TIME_RESPONSE = 1  # UFF58 function types
FRF = 4
COHERENCE = 6
ABSCISSA_TIME = 17  # UFF58 specific data types
ABSCISSA_FREQUENCY = 18
ORDINATE_UNKNOWN = 0
ORDINATE_ACCELERATION = 12
ORDINATE_FORCE = 13
AXES = "XYZ"
HAMMER_DIR = 3  # the hammer strikes the top disc vertically

# factor from an ordinate's unit label to SI (m/s² or N); labels are compared lower-case without spaces
ACCEL_UNITS = {"m/s^2": 1.0, "m/s2": 1.0, "m/s**2": 1.0, "m/s²": 1.0, "ms^-2": 1.0, "mm/s^2": 1e-3,
               "mm/s2": 1e-3, "mm/s²": 1e-3, "g": 9.80665, "gn": 9.80665}
FORCE_UNITS = {"n": 1.0, "kn": 1e3, "lbf": 4.4482216152605, "lb": 4.4482216152605}
NO_UNIT = {"", "none", "unknown", "-"}


@dataclass(frozen=True)
class NodeMap:
    """Which UFF node is which sensor: accelerometer name (``A1``…) → node, and the hammer's node."""

    sensors: dict[str, int] = field(default_factory=lambda: {"A1": 1, "A2": 2, "A3": 3, "A4": 4})
    hammer: int = 10

    def __post_init__(self) -> None:
        nodes = [*self.sensors.values(), self.hammer]
        if len(set(nodes)) != len(nodes):
            raise InputError(f"node map {self.describe()}: every sensor and the hammer need their own node")

    def channel(self, node: int, direction: int) -> tuple[str, float] | None:
        """(channel name, sign) of a response record, or None for a node that is no accelerometer.

        A negative direction is the sensor's axis pointing the other way: its record is negated.
        """
        if abs(direction) not in (1, 2, 3):
            return None
        for name, n in self.sensors.items():
            if n == node:
                return f"{name}{AXES[abs(direction) - 1]}", 1.0 if direction > 0 else -1.0
        return None

    def node_dir(self, channel: str) -> tuple[int, int]:
        """(node, direction) of a channel name such as ``A3Z``."""
        sensor, axis = channel[:-1], channel[-1:]
        if sensor not in self.sensors or axis not in AXES:
            raise InputError(f"channel {channel!r} has no UFF node (known sensors {', '.join(self.sensors)}, "
                             "axes X/Y/Z)")
        return self.sensors[sensor], AXES.index(axis) + 1

    def describe(self) -> str:
        return ",".join([*(f"{k}={v}" for k, v in self.sensors.items()), f"hammer={self.hammer}"])


DEFAULT_NODES = NodeMap()


def parse_node_map(text: str | None) -> NodeMap:
    """A node map from ``A1=101,A2=102,A3=103,A4=104,hammer=1``; sensors not named keep their default node."""
    if not text:
        return DEFAULT_NODES
    sensors, hammer = dict(DEFAULT_NODES.sensors), DEFAULT_NODES.hammer
    for item in (p.strip() for p in text.split(",") if p.strip()):
        m = re.fullmatch(r"(A[1-9]|hammer)\s*=\s*(\d+)", item, flags=re.IGNORECASE)
        if not m:
            raise InputError(f"node map entry {item!r}: expected NAME=NODE with NAME one of A1…A4 or hammer, "
                             "e.g. 'A1=101,hammer=1'")
        name, node = m.group(1), int(m.group(2))
        if name.lower() == "hammer":
            hammer = node
        else:
            sensors[name.upper()] = node
    return NodeMap(sensors, hammer)


def unit_factor(label: str, accel: bool, where: str) -> float:
    """SI factor for an ordinate unit label; an empty or 'NONE' label is taken as SI already."""
    key = "".join(str(label).split()).lower()
    if key in NO_UNIT:
        return 1.0
    table = ACCEL_UNITS if accel else FORCE_UNITS
    if key in table:
        return table[key]
    expected = "m/s^2, mm/s^2 or g" if accel else "N, kN or lbf"
    raise InputError(f"{where}: ordinate unit {label!r} is not understood; expected {expected}")
