"""Reads of a live file run in a child process: a crash there (HDF5 can segfault on metadata torn by a
concurrent flush) costs one read, raised as TornRead, and the next read works on a fresh child."""

from __future__ import annotations

import os
import signal

import pytest

from labctl.errors import InputError
from labctl.storage.isolated import TornRead, call_isolated

pytestmark = pytest.mark.waits  # on other processes or real time (tests/conftest.py)


def crash() -> None:
    os.kill(os.getpid(), signal.SIGSEGV)


def hang() -> None:
    signal.pause()


def refuse(path: str) -> None:
    raise InputError(f"{path}: not a labctl campaign file")


def test_a_crash_in_the_reading_child_is_a_torn_read_and_the_next_read_works():
    first = call_isolated(os.getpid)
    assert first != os.getpid()  # the read ran elsewhere
    with pytest.raises(TornRead, match="died"):
        call_isolated(crash)
    second = call_isolated(os.getpid)
    assert second not in (first, os.getpid())  # a fresh child after the crash


def test_a_hung_read_is_stopped_and_reported():
    with pytest.raises(TornRead, match="no answer"):
        call_isolated(hang, timeout_s=0.5)
    assert call_isolated(sum, [1, 2, 3]) == 6


def test_the_readers_own_errors_come_back_as_they_were_raised():
    with pytest.raises(InputError, match="x.h5: not a labctl campaign file"):
        call_isolated(refuse, "x.h5")
    assert call_isolated(len, "abc") == 3  # the child survived a raised error
