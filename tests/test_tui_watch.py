"""``labctl tui --watch FILE``: follows a campaign another process writes, read-only, to its end; the snapshot
reader retries reads that catch a flush half-way; ``--serve`` builds the command each browser session runs."""

from __future__ import annotations

import asyncio
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from labctl.cli.tui import serve_command
from labctl.errors import InputError
from labctl.storage import CampaignReader
from labctl.tui import LabApp, TuiSettings
from labctl.tui.watch import read_snapshot
from labctl.tui.watcher import WatchScreen
from tests.cli_util import shipped_environment
from tests.engine_util import stepped_protocol_text
from tests.test_tui import SIZE, wait_for

pytestmark = pytest.mark.waits  # on other processes or real time (tests/conftest.py)

ROOT = Path(__file__).resolve().parents[1]


def _stop_group(proc: subprocess.Popen) -> None:
    """End a process started in its own process group, and everything it started: TERM, then KILL."""
    os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(20)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(20)


async def test_watch_follows_a_running_labctl_run_to_complete(tmp_path: Path):
    out = tmp_path / "watched.h5"
    protocol = tmp_path / "watched.toml"  # 1 repetition of 3 steps: the run is held until it is seen running
    protocol.write_text(stepped_protocol_text("watched", 1, 300.0, 3, 1), encoding="utf-8")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "labctl", "run", str(protocol), "--out", str(out), "--quiet",
                             "--seed", "4"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=tmp_path)
    app = LabApp(TuiSettings(), watch_path=out, watch_interval_s=0.1)
    seen: list[str] = []

    async def hold_until_seen_running() -> None:
        """The twin runs on virtual time and may finish a short campaign between two polls: once the file is
        there, stop the run (up to 1.5 s at a time) until the watcher has seen it running, as it would see a run
        on the real rig; a read that caught a flush half-way is retried at the next poll."""
        while proc.poll() is None and "running" not in seen:
            if not out.exists():
                await asyncio.sleep(0.02)
                continue
            proc.send_signal(signal.SIGSTOP)
            try:
                for _ in range(30):
                    if "running" in seen:
                        break
                    await asyncio.sleep(0.05)
            finally:
                proc.send_signal(signal.SIGCONT)
            await asyncio.sleep(0.05)

    holder = asyncio.create_task(hold_until_seen_running())
    try:
        async with app.run_test(size=SIZE) as pilot:
            screen = await wait_for(pilot, lambda: isinstance(app.screen, WatchScreen) and app.screen)
            original = screen.update_from

            def spy(snap, problem):  # noqa: ANN001, ANN202
                seen.append(snap.status if snap is not None else f"unreadable: {problem}")
                original(snap, problem)

            screen.update_from = spy
            await wait_for(pilot, lambda: screen.snapshot is not None and screen.snapshot.finished, timeout_s=240,
                           what="the watched campaign to end")
            header = str(screen.query_one("#w-header").render())
            rows = screen.query_one("#w-steps").row_count
    finally:
        holder.cancel()
        if proc.poll() is None:
            proc.send_signal(signal.SIGCONT)
        proc.wait(timeout=240)
    assert proc.returncode == 0, proc.stderr.read()
    assert header.startswith("COMPLETE") and "watched on sim" in header
    assert "running" in seen, seen  # it followed the campaign while it ran, not only its end
    with CampaignReader(out, locking=False) as reader:  # as the watcher opened it in this process
        stored = [st for run in reader.runs(1) for st in run.steps]
        assert reader.attrs["status"] == "complete"
    assert rows == len(stored)
    snap = read_snapshot(out)
    assert snap.accepted == sum(st.accepted_count for st in stored) and snap.finished


def test_a_read_that_ends_after_the_watch_screen_closed_is_dropped(tmp_path: Path):
    # the poll reads in a worker thread; under load a read finished after the app had torn the screen's widgets
    # down, and handing it over raised NoMatches('#w-steps') out of the worker (a fresh clone's CI run failed so).
    screen = WatchScreen(tmp_path / "gone.h5", 0.1)
    screen.update_from(None, "the file is being written")
    assert screen.problem == "the file is being written"


def test_a_missing_or_foreign_file_is_said_and_a_foreign_file_is_not_retried(tmp_path: Path):
    with pytest.raises(InputError, match="not found"):
        read_snapshot(tmp_path / "nope.h5", attempts=2, wait_s=0.0)
    foreign = tmp_path / "foreign.h5"
    import h5py

    h5py.File(foreign, "w").close()
    with pytest.raises(InputError, match="not a labctl campaign"):
        read_snapshot(foreign, attempts=50, wait_s=1.0)  # refused at once, not after 50 s of retries


def test_serve_listens_on_this_machine_only_unless_told():
    from labctl.cli import build_parser

    args = build_parser().parse_args(["tui", "--watch", "c.h5", "--serve"])
    assert args.host == "127.0.0.1" and args.port == 8000


def test_serve_runs_the_same_tui_command_without_the_serve_options():
    cmd = serve_command(["tui", "--watch", "c.h5", "--serve", "--host", "0.0.0.0", "--port=8080"])
    assert cmd.endswith("-m labctl tui --watch c.h5") and "--serve" not in cmd and "8080" not in cmd


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
@pytest.mark.skipif(not shutil.which("chromium-headless-shell"), reason="needs chromium-headless-shell")
def test_serve_shows_the_watch_screen_in_headless_chromium(tmp_path: Path):
    """``labctl tui --watch FILE --serve``: bound to 127.0.0.1; a headless Chromium page receives the app (its
    terminal gets the first bytes), and what the page receives carries the header (WATCHING … COMPLETE)."""
    import asyncio

    from tests.engine_util import short_campaign_file

    campaign = short_campaign_file(tmp_path / "c.h5", seed=3, reps=1)
    port = _free_port()
    env = shipped_environment(PYTHONPATH=str(ROOT))
    server = subprocess.Popen([sys.executable, "-m", "labctl", "tui", "--watch", str(campaign), "--serve",
                               "--port", str(port)], env=env, cwd=tmp_path, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        body, output = asyncio.run(_browse(f"127.0.0.1:{port}"))
    finally:  # the server and the sessions it started: their own process group
        _stop_group(server)
    assert "-first-byte" in body  # the app's output reached the page
    assert b"WATCHING (read-only)" in output and b"COMPLETE" in output


async def _browse(host: str) -> tuple[str, bytes]:
    """Open the served page in headless Chromium (DevTools protocol) until the app has drawn its header, and
    collect what the page's own websocket received (the DevTools Network events carry its frames)."""
    import asyncio
    import base64

    import aiohttp

    async with aiohttp.ClientSession() as http:
        for _ in range(600):  # the server imports textual-serve and starts
            try:
                async with http.get(f"http://{host}/") as r:
                    if r.status == 200:
                        break
            except aiohttp.ClientError:
                pass
            await asyncio.sleep(0.1)
        chrome = subprocess.Popen(["chromium-headless-shell", "--no-sandbox", "--headless", "--disable-gpu",
                                   "--remote-debugging-port=0", "--window-size=1200,800", "about:blank"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                  start_new_session=True)
        try:
            devtools = ""
            while not devtools:
                line = chrome.stderr.readline()
                if not line:
                    raise AssertionError("chromium did not start")
                if "DevTools listening on " in line:
                    devtools = line.split("DevTools listening on ", 1)[1].strip()
            debug = devtools.split("/devtools/")[0].replace("ws://", "http://")
            async with http.get(f"{debug}/json") as r:
                page = next(p for p in await r.json() if p["type"] == "page")
            body, output, n = "", b"", 0
            async with http.ws_connect(page["webSocketDebuggerUrl"], max_msg_size=0) as cdp:

                async def call(method: str, **params: object) -> dict:
                    """One DevTools command; the frames the page's websocket receives meanwhile are collected."""
                    nonlocal n, output
                    n += 1
                    await cdp.send_json({"id": n, "method": method, "params": params})
                    while (reply := await cdp.receive_json()).get("id") != n:
                        if reply.get("method") == "Network.webSocketFrameReceived":
                            frame = reply["params"]["response"]
                            data = frame["payloadData"]
                            output += base64.b64decode(data) if frame["opcode"] == 2 else data.encode()
                    return reply

                await call("Network.enable")  # before the page opens its websocket: every frame is seen
                await call("Page.navigate", url=f"http://{host}/")
                for _ in range(600):
                    reply = await call("Runtime.evaluate", expression="document.body.className")
                    body = str(reply.get("result", {}).get("result", {}).get("value", ""))
                    if "-first-byte" in body and b"WATCHING" in output and b"COMPLETE" in output:
                        break
                    await asyncio.sleep(0.1)
        finally:  # chromium and its helpers: their own process group
            _stop_group(chrome)
        return body, output


def test_a_read_is_taken_only_as_an_earlier_state_of_the_next(tmp_path: Path):
    """The writer only appends: a read whose finished step differs from the next read's, or that holds more
    impacts than the next, caught a flush half-way and is not shown."""
    from dataclasses import replace

    from labctl.tui.watch import Snapshot, WatchedStep

    done = WatchedStep(1, 1, 1, 38.0, 2, 2, True, 500.0, 2.2e7, (), True)
    going = WatchedStep(1, 1, 2, 118.0, 1, 1, False, float("nan"), float("nan"), (), False)
    early = Snapshot("f.h5", "running", "p", "sim", (done, going), ("a",))
    later = Snapshot("f.h5", "running", "p", "sim", (done, replace(going, impacts=2, accepted=2)), ("a", "b"))
    assert early.earlier_state_of(later) and early.earlier_state_of(early)
    assert not later.earlier_state_of(early)  # impacts do not go away
    torn = Snapshot("f.h5", "running", "p", "sim", (replace(done, bounce_hz=0.0), going), ("a",))
    assert not torn.earlier_state_of(later)  # a finished step never changes
    assert not replace(early, log=("x",)).earlier_state_of(later)  # the run log only grows
