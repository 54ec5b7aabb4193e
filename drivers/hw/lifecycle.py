"""The context-manager lifecycle every instrument shares: ``with instrument:`` opens it and always closes it."""

from __future__ import annotations

from typing import Self


class Lifecycle:
    """Base for instruments: subclasses override ``open``/``close`` when they hold a resource."""

    def open(self) -> None:
        return None

    def close(self) -> None:
        return None

    def __enter__(self) -> Self:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
