"""The technician's screen in a real 100×30 terminal (tmux): the per-hit gate, the load-drift prompt and the
browser are readable whole — no title, header or footer cut off mid-word — and the header says what is asked.

The simulated world is the default one with a knob nut that always creeps (so step 1's load drifts) and a cable
pulled at the seating; the test answers as a technician would and keeps the three screens in ``tmp_path``
(``LABCTL_SCREENSHOTS=DIR`` copies them there).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
COLS, ROWS = 100, 30

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(not shutil.which("tmux"), reason="needs tmux")]


SOCKET = f"labctl-h28-{os.getpid()}"  # a server of its own: another client cannot shrink the window


def tmux(*args: str, check: bool = False) -> str:
    return subprocess.run(["tmux", "-L", SOCKET, *args], capture_output=True, text=True, check=check).stdout


def capture(session: str) -> str:
    return tmux("capture-pane", "-p", "-t", session)


def keys(session: str, *k: str) -> None:
    tmux("send-keys", "-t", session, *k, check=True)


def assert_whole(pane: str, what: str) -> None:
    """Nothing on the screen is cut: no ellipsis, and the pane holds its 30 rows of at most 100 columns."""
    assert "…" not in pane, f"{what}: a cut word\n{pane}"
    lines = pane.rstrip("\n").split("\n")
    assert len(lines) <= ROWS and all(len(line) <= COLS for line in lines), pane


def test_gate_drift_prompt_and_browser_are_readable_at_100x30(tmp_path: Path):
    world = tmp_path / "creeping.toml"
    world.write_text((ROOT / "labctl/data/worlds/default.toml").read_text(encoding="utf-8")
                     + "\n[faults]\ncreep_rate = 1.0\ncreep_n_per_s = -10.0\ndead_channel_rate = 1.0\n",
                     encoding="utf-8")
    session = f"labctl-h28-{os.getpid()}"
    cmd = (f"env -u COLUMNS -u LINES PYTHONPATH={ROOT} {sys.executable} -m labctl tui quick_check --autostart "
           f"--no-auto-confirm --world {world} --seed 2 --out t.h5")
    tmux("new", "-d", "-s", session, "-x", str(COLS), "-y", str(ROWS), "-c", str(tmp_path), cmd, check=True)
    shots: dict[str, str] = {}
    try:
        deadline = time.monotonic() + 240
        pane = ""
        while time.monotonic() < deadline:
            time.sleep(0.7)
            pane = capture(session)
            if "COMPLETE" in pane:
                break
            if "JUDGE THE BLOW" in pane and "accept (y)" in pane:
                if "gate" not in shots:
                    time.sleep(1.0)  # the whole dialog drawn, its footer too
                    shots["gate"] = capture(session)
                keys(session, "y")
            elif "JUDGE THE BLOW" in pane and "reject (r)" in pane:
                keys(session, "r")
            elif "drifted" in pane and "WAITING FOR YOU" in pane:
                if "drift" not in shots:
                    time.sleep(1.0)
                    shots["drift"] = capture(session)
                keys(session, "1")
            elif "WAITING FOR YOU" in pane:
                keys(session, "Enter")
        assert "COMPLETE" in pane, pane
        keys(session, "o")
        time.sleep(2.0)
        keys(session, "Down", "Down", "Down")
        time.sleep(1.5)
        shots["browser"] = capture(session)
        keys(session, "Escape")
        time.sleep(0.5)
        keys(session, "q")
        time.sleep(1.0)
    finally:
        tmux("kill-server")
    keep = Path(os.environ.get("LABCTL_SCREENSHOTS", tmp_path))
    keep.mkdir(parents=True, exist_ok=True)
    for name, shot in shots.items():
        (keep / f"tui_{name}_{COLS}x{ROWS}.txt").write_text(shot, encoding="utf-8")
    assert {"gate", "drift", "browser"} <= shots.keys(), sorted(shots)
    gate, drift, browser = shots["gate"], shots["drift"], shots["browser"]
    assert "JUDGE THE BLOW: y accept · r reject (nothing armed)" in gate and "ARMED" not in gate.replace(
        "nothing armed", "")
    assert "y accept  r reject  p pause  a abort" in gate  # the gate's footer, not hidden under it
    assert "WAITING FOR YOU: Please confirm (nothing armed)" in drift and "1 continue" in drift
    assert "LOAD DRIFTED" in browser and "left out" in browser
    for name, shot in shots.items():
        assert_whole(shot, name)
