"""Hardware calls with a deadline and bounded retries, so no instrument can hang or end a campaign silently."""

from __future__ import annotations

import concurrent.futures as cf
from collections.abc import Callable
from typing import Any, TypeVar

from drivers.errors import DeviceError, DeviceTimeout
from labctl.errors import LabctlError

T = TypeVar("T")
_DEFAULT = object()


class HardwareFailure(LabctlError):
    """An instrument kept failing after the allowed retries; names the device, the action and the cause."""


class GuardedCaller:
    """Runs instrument calls in a worker thread with a deadline; retries typed device errors a bounded number."""

    def __init__(self, timeout_s: float, retries: int, on_retry: Callable[[str], None] | None = None) -> None:
        self.timeout_s, self.retries, self.on_retry = timeout_s, retries, on_retry
        self._pool = cf.ThreadPoolExecutor(max_workers=1, thread_name_prefix="labctl-hw")

    def __call__(self, what: str, fn: Callable[..., T], *args: Any, timeout_s: float | None | object = _DEFAULT,
                 retries: int | None = None) -> T:
        """Call ``fn(*args)`` within ``timeout_s`` (the default deadline; None = wait as long as it takes)."""
        limit = self.timeout_s if timeout_s is _DEFAULT else timeout_s
        attempts = 1 + (self.retries if retries is None else retries)
        last: Exception | None = None
        for attempt in range(1, attempts + 1):
            future = self._pool.submit(fn, *args)
            try:
                return future.result(timeout=limit)
            except cf.TimeoutError:
                # the stuck call keeps its thread; use a fresh worker for the next attempt
                self._pool.shutdown(wait=False, cancel_futures=True)
                self._pool = cf.ThreadPoolExecutor(max_workers=1, thread_name_prefix="labctl-hw")
                last = DeviceTimeout(what, "call", f"no answer within {limit} s")
            except DeviceError as exc:
                last = exc
            if attempt < attempts and self.on_retry:
                self.on_retry(f"{what}: {last}; retrying ({attempt}/{attempts - 1})")
        raise HardwareFailure(f"{what} failed after {attempts} attempt(s): {last}")

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)
