"""Checks against the real instruments of a rig; deselected by default (``-m 'not hardware'``).

Run at the rig with ``LABCTL_DEVICES=devices.toml python -m pytest -m hardware tests/test_hw_real.py``.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from drivers.interfaces import TriggerSpec
from drivers.operators import ConsoleOperator
from labctl.hardware import DEVICES_ENV, check_devices, make_hw_rig

pytestmark = pytest.mark.hardware


@pytest.fixture
def devices() -> str:
    path = os.environ.get(DEVICES_ENV)
    if not path:
        pytest.skip(f"set {DEVICES_ENV} to the rig's devices file")
    return path


def test_every_configured_instrument_answers(devices: str) -> None:
    failed = [c for c in check_devices(devices) if not c.ok]
    assert not failed, "; ".join(f"{c.role}: {c.detail}" for c in failed)


def test_load_cell_reads_at_least_the_preload(devices: str) -> None:
    with make_hw_rig(devices, operator=ConsoleOperator()).load_cell as cell:
        reading = cell.read()
    assert reading.force_n > 50.0  # the upper disc and rails weigh ~115 N on the three rollers


def test_one_blow_is_recorded(devices: str) -> None:
    rig = make_hw_rig(devices, operator=ConsoleOperator())
    with rig.daq as daq, rig.hammer as hammer:
        fs = daq.configure(20480.0, 65536)
        daq.arm(TriggerSpec(level_n=20.0, pretrigger_samples=256))
        hammer.strike()
        record = daq.acquire(timeout_s=60.0)
    # the record keeps the protocol's 3.2 s and 12.5 ms pretrigger at whatever rate the DAQ runs (NI: 51.2 kS/s ÷ n)
    assert record.sample_rate_hz == fs and record.trigger_index == round(256 * fs / 20480.0)
    assert record.force_n.size / fs == pytest.approx(3.2, abs=1 / fs)
    assert record.force_n.max() > 20.0 and np.all(np.isfinite(record.accel_m_per_s2))


def test_first_day_tap_check_has_no_failed_row(devices: str) -> None:
    from drivers.hw.verify import FAILED
    from labctl.hardware import tap_check_devices

    rows = tap_check_devices(devices, ConsoleOperator())
    assert not [r for r in rows if r.status == FAILED], [r for r in rows if r.status == FAILED]
