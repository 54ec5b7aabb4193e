"""Kill test: SIGKILL a running campaign, resume it, and find every step exactly once and old impacts unchanged."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

from labctl.storage import CampaignReader
from tests.cli_util import labctl
from tests.engine_util import short_protocol

pytestmark = pytest.mark.waits  # on other processes or real time (tests/conftest.py)


def _labctl_cmd(*args: str) -> list[str]:
    exe = shutil.which("labctl")
    return [exe, *args] if exe else [sys.executable, "-m", "labctl", *args]


def _impacts(path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    out = {}
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            is_impact = isinstance(obj, h5py.Group) and name.rsplit("/", 1)[-1].startswith("impact_")
            if is_impact and obj.attrs.get("complete"):
                out[name] = (obj["force_n"][()], obj["accel_m_per_s2"][()])
        f.visititems(visit)
    return out


@pytest.mark.slow
def test_sigkill_then_resume_holds_every_step_once_and_keeps_old_impacts(tmp_path):
    # 2 repetitions of 5 steps (180° knob steps up to 200 N), 2 blows of 8192 samples each: 20 impacts
    protocol = tmp_path / "short.toml"
    protocol.write_text(short_protocol(max_load=200.0, step=180.0, samples=8192, impacts=2, reps=2).source_text)
    out = tmp_path / "c.h5"
    proc = subprocess.Popen(_labctl_cmd("run", str(protocol), "--backend", "sim", "--out", str(out), "--seed", "5"),
                            stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True,
                            cwd=os.path.dirname(os.path.dirname(__file__)))
    seen = 0
    deadline = time.monotonic() + 240
    assert proc.stderr is not None
    for line in proc.stderr:
        if " impacts · ETA" in line:
            seen += 1
        if seen >= 13 or time.monotonic() > deadline:  # into the second repetition (10 impacts each)
            break
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert seen >= 13, "the run did not get far enough before the kill"
    with CampaignReader(out) as r:  # first: a kill inside a flush is rolled back by any labctl read
        assert r.attrs["status"] == "running"  # killed: never marked finished
    before = _impacts(out)
    assert len(before) >= 12

    # the resume needs no fresh interpreter: the CLI in this process (tests/cli_util.py)
    done = labctl("run", str(protocol), "--backend", "sim", "--out", str(out), "--resume", "--quiet")
    assert done.returncode == 0, done.stderr
    after = _impacts(out)
    for name, (force, accel) in before.items():
        assert np.array_equal(after[name][0], force) and np.array_equal(after[name][1], accel), name
    with CampaignReader(out) as r:
        assert r.attrs["status"] == "complete"
        runs = r.runs(1)
        assert len(runs) == 2 and all(run.complete for run in runs)
        for run in runs:
            steps = [s.step for s in run.steps]
            assert steps == list(range(1, len(steps) + 1)) and len(steps) >= 4
            for s in run.steps:
                assert s.complete and s.accepted_count == 2 and s.result is not None
            assert r.curve(1, run.run)["load_n"].size == len(steps)
