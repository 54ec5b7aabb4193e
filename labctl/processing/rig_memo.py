"""What processing derives from a rig object and a channel list (predicted shapes, sensor maps), built once per
rig: a campaign identifies every step against the same, immutable rig."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Generic, TypeVar

from labctl.physics import RigConfig

T = TypeVar("T")
MEMO_SIZE = 16
"""Rig/channel combinations kept; more (a long-running process over many rigs) start the memo afresh."""


class RigMemo(Generic[T]):
    """``build(rig, channels)`` remembered per rig object (by identity, checked on a hit) and channel tuple."""

    def __init__(self, build: Callable[[RigConfig, Sequence[str]], T]) -> None:
        self.build = build
        self._memo: dict[tuple[int, tuple[str, ...]], tuple[RigConfig, T]] = {}

    def __call__(self, rig: RigConfig, channels: Sequence[str]) -> T:
        key = (id(rig), tuple(channels))
        hit = self._memo.get(key)
        if hit is not None and hit[0] is rig:
            return hit[1]
        if len(self._memo) > MEMO_SIZE:
            self._memo.clear()
        value = self.build(rig, key[1])
        self._memo[key] = (rig, value)
        return value
