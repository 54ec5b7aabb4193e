"""The protocol's ``[static]`` table: the paper's static load–displacement method (§2.5), alone or with the hammer.

``method = "combined"`` takes a static reading and the hammer impacts at every load step (the paper's Fig. 8
comparison); ``method = "static"`` takes the static reading only. The sensor's thermal drift is given in nm/min
(its datasheet value for the lab's temperature stability) and kept in SI (m/s): it is the one part of the
static uncertainty the readings cannot show.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

from labctl.data.schema import Integer, Number, Spec, Table, Text, Where, read, value

StaticMethod = Literal["combined", "static"]
NM_PER_MIN = 1e-9 / 60.0

STATIC: dict[str, Spec] = {
    "method": Text({"combined": "hammer and static at each step", "static": "static only, no hammer"},
                   default="combined"),
    "reads": Integer(2, 100, default=5),
    "drift_nm_per_min": Number(ge=0, le=1e4, default=10.0),
}


@dataclass(frozen=True)
class StaticSpec:
    """How each step's static point is read: ``reads`` pairs of (load-cell reading, displacement DC average),
    and the displacement sensor's drift (1 σ of its rate, m/s)."""

    method: StaticMethod = "combined"
    reads: int = 5
    drift_m_per_s: float = 10.0 * NM_PER_MIN

    @property
    def hammer(self) -> bool:
        """Whether the hammer impacts are taken too."""
        return self.method == "combined"


def parse_static(doc: dict[str, Any], top: Where) -> StaticSpec | None:
    """The ``[static]`` table of a protocol document (None when it has none: a hammer-only protocol)."""
    if "static" not in doc:
        return None
    where = top.at("static")
    t = read(value(doc, "static", Table(), top), STATIC, where)
    return StaticSpec(method=t["method"], reads=t["reads"], drift_m_per_s=t["drift_nm_per_min"] * NM_PER_MIN)
