"""The technician's screen in a real 100×30 terminal (tmux): the per-hit gate, the load-drift prompt and the
browser are readable whole — no title, header or footer cut off mid-word — and the header says what is asked.

The simulated world is the default one with a knob nut that always creeps (so step 1's load drifts) and a cable
pulled at the seating; the test answers as a technician would (waiting for the screen to take each key), aborts
once step 2 is under way (step 1 showed all three), browses the file and keeps the three screens in ``tmp_path``
(``LABCTL_SCREENSHOTS=DIR`` copies them there).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
COLS, ROWS = 100, 30

pytestmark = [pytest.mark.slow, pytest.mark.waits,
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


def dialog_lines(pane: str) -> list[str]:
    """The open dialog's text rows (inside its thick border): which dialog is up, and which blow it is about."""
    return [line for line in pane.split("\n") if re.search(r"█  \S", line)]


def wait_until(session: str, done, timeout_s: float = 20.0) -> str:  # noqa: ANN001
    """Capture the pane every 50 ms until ``done(pane)``; the last capture (the caller asserts on it)."""
    deadline = time.monotonic() + timeout_s
    pane = capture(session)
    while not done(pane) and time.monotonic() < deadline:
        time.sleep(0.05)
        pane = capture(session)
    return pane


def settled(session: str, *texts: str, after: str = "") -> str:
    """The pane once it shows every one of ``texts``, differs from ``after`` (the keys sent were taken) and two
    captures 0.15 s apart agree (the frame is whole)."""
    last = ""

    def whole(pane: str) -> bool:
        nonlocal last
        ok = all(t in pane for t in texts) and pane != after and pane == last
        if not ok:
            time.sleep(0.15)
        last = pane
        return ok

    return wait_until(session, whole)


def test_gate_drift_prompt_and_browser_are_readable_at_100x30(tmp_path: Path):
    world = tmp_path / "creeping.toml"
    world.write_text((ROOT / "labctl/data/worlds/default.toml").read_text(encoding="utf-8")
                     + "\n[faults]\ncreep_rate = 1.0\ncreep_n_per_s = -10.0\ndead_channel_rate = 1.0\n",
                     encoding="utf-8")
    session = f"labctl-h28-{os.getpid()}"
    cmd = (f"env -u COLUMNS -u LINES -u TEXTUAL_FPS PYTHONPATH={ROOT} {sys.executable} -m labctl tui quick_check "
           f"--autostart --no-auto-confirm --world {world} --seed 2 --out t.h5")
    tmux("new", "-d", "-s", session, "-x", str(COLS), "-y", str(ROWS), "-c", str(tmp_path), cmd, check=True)
    shots: dict[str, str] = {}
    try:
        deadline = time.monotonic() + 240
        pane = ""
        while time.monotonic() < deadline:
            time.sleep(0.1)
            pane = capture(session)
            if "COMPLETE" in pane:
                break
            if "JUDGE THE BLOW" in pane and shots.keys() >= {"gate", "drift"} and re.search(
                    r"Step [2-9] impact \d+:", pane):  # step 2 under way: the rest of the campaign shows nothing new
                keys(session, "a")
                wait_until(session, lambda now: "Abort the campaign?" in now)
                keys(session, "x")
                pane = wait_until(session, lambda now: "ABORTED" in now)
                break
            if "JUDGE THE BLOW" not in pane and "WAITING FOR YOU" not in pane:
                continue
            # Judge what is asked on a whole frame, by the dialog's own text: a frame caught mid-redraw can show a
            # header before its dialog's text, and "drifted" stays in the log long after its prompt was answered.
            pane = settled(session)
            asked = "\n".join(dialog_lines(pane))
            if "JUDGE THE BLOW" in pane and "accept (y)" in pane:
                if "gate" not in shots:  # the whole dialog drawn, its footer too
                    pane = shots["gate"] = settled(session, "JUDGE THE BLOW", "accept (y)", "y accept  r reject")
                key = "y"
            elif "JUDGE THE BLOW" in pane and "reject (r)" in pane:
                key = "r"
            elif "drifted" in asked and "WAITING FOR YOU" in pane:
                if "drift" not in shots:
                    pane = shots["drift"] = settled(session, "drifted", "WAITING FOR YOU", "1 continue")
                key = "1"
            elif "WAITING FOR YOU" in pane and asked:
                key = "Enter"
            else:
                continue
            keys(session, key)  # then wait for the screen to take it: that dialog gone (another may be up)
            shown = dialog_lines(pane)
            wait_until(session, lambda now, shown=shown: dialog_lines(now) != shown, timeout_s=10)
        assert "COMPLETE" in pane or "ABORTED" in pane, pane
        # as a technician would: the finished screen whole, its footer offering the browser, before the key
        settled(session, "o open", "COMPLETE" if "COMPLETE" in pane else "ABORTED")
        keys(session, "o")
        opened = settled(session, "select a series")  # the browser, nothing selected yet
        keys(session, "Down", "Down", "Down")
        shots["browser"] = settled(session, "LOAD DRIFTED", "left out", after=opened)
        keys(session, "Escape")
        wait_until(session, lambda now: "COMPLETE" in now or "ABORTED" in now, timeout_s=10)
        keys(session, "q")
        wait_until(session, lambda now: not now.strip(), timeout_s=10)  # the app quit, its session with it
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
