"""No campaign lost: a full disk (a file-size limit in a child process, at three sizes), a write that fails
mid-impact, an error at step 2, SIGTERM and SIGHUP all leave a file that `process` reads and `--resume`
completes, with the status telling the truth and the step plan of an uninterrupted run.

The campaigns are quick_check with short records (8192 samples) so that each runs in about a second.
"""

from __future__ import annotations

import errno
import multiprocessing
import os
import resource
import signal
import sys
import threading
import time
from pathlib import Path

import h5py
import pytest

from labctl.storage import CampaignReader
from tests.cli_util import labctl_here, labctl_here_json

SMALL = """[protocol]
name = "quick_check_small"
description = "quick_check with short records"
version = 1

[specimen]
kind = "roller"
roller_type = 1
rail_ra_um = 0.2
max_load_n = 200.0
knob_step_deg = 360.0

[acquisition]
samples = 8192
impacts_per_step = 2

[repetitions]
count = 1
"""
FORK = multiprocessing.get_context("fork")


@pytest.fixture(scope="module")
def protocol(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("proto") / "small.toml"
    path.write_text(SMALL, encoding="utf-8")
    return path


def _status(path: Path) -> tuple[str, str]:
    with CampaignReader(path) as r:
        return str(r.attrs.get("status")), str(r.attrs.get("status_message", ""))


def _impacts(path: Path) -> int:
    with h5py.File(path, "r") as f:
        return sum(1 for name in _names(f) if name.rsplit("/", 1)[-1].startswith("impact_"))


def _names(f: h5py.File) -> list[str]:
    out: list[str] = []
    f.visit(out.append)
    return out


def _plan(path: Path) -> list[tuple[int, float, float]]:
    """(step, knob angle, measured load) of every step of the campaign."""
    with CampaignReader(path) as r:
        return [(s.step, s.knob_angle_deg, s.load_n) for run in r.runs(1) for s in run.steps]


def _stored_vs_processed(capsys, path: Path) -> None:
    """`labctl process` identifies every step as the run stored it."""
    with CampaignReader(path) as r:
        stored = {s.step: s.result.roller_stiffness_n_per_m for run in r.runs(1) for s in run.steps
                  if s.result is not None and s.result.identified}
    done = labctl_here_json(capsys, "process", str(path))
    again = {s["step"]: s["roller_stiffness_n_per_m"] for s in done["steps"] if not s["error"]}
    assert stored and again.keys() == stored.keys()
    for step, k in stored.items():
        assert again[step] == pytest.approx(k, rel=1e-9), step


def _child(argv: list[str], limit: int | None, log: str) -> None:
    """A forked `labctl` (no interpreter start-up): optional file-size limit, output to ``log``."""
    fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    sys.stdout = sys.stderr = os.fdopen(os.dup(fd), "w", buffering=1)  # not pytest's capture
    if limit is not None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # as CPython sets it at start-up: EFBIG, not death
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, resource.RLIM_INFINITY))
    from labctl.cli import main

    code = main(argv)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


@pytest.mark.parametrize("limit_mb", [5.0, 5.4, 5.8])
def test_a_full_disk_stops_cleanly_and_resume_completes(limit_mb: float, protocol: Path, tmp_path: Path, capsys):
    out, log = tmp_path / "c.h5", tmp_path / "log.txt"
    proc = FORK.Process(target=_child, args=(["run", str(protocol), "--out", str(out), "--seed", "4", "--quiet"],
                                             int(limit_mb * 1e6), str(log)))
    proc.start()
    proc.join(120)
    text = log.read_text()
    assert proc.exitcode == 130, text  # interrupted, not a crash (no segfault: exit code -11)
    assert "Traceback" not in text and "disk full" in text and "free space and --resume" in text
    status, message = _status(out)
    assert status == "interrupted" and "disk full" in message
    kept = _impacts(out)
    assert 0 <= kept < 6
    assert labctl_here(capsys, "process", str(out)).returncode == 0  # what was kept is processable

    done = labctl_here_json(capsys, "run", str(protocol), "--out", str(out), "--resume", "--quiet")
    assert done["status"] == "complete"
    assert _status(out)[0] == "complete" and _impacts(out) >= 6
    _stored_vs_processed(capsys, out)


def test_a_write_failing_mid_impact_is_rolled_back(protocol: Path, tmp_path: Path, capsys, monkeypatch):
    import labctl.storage.writer as writer

    real, calls = writer._write_trace, []

    def failing(*args, **kw):  # the third trace written (the second impact's force) meets a full disk
        calls.append(1)
        if len(calls) == 3:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(*args, **kw)

    monkeypatch.setattr(writer, "_write_trace", failing)
    out = tmp_path / "c.h5"
    proc = labctl_here(capsys, "run", str(protocol), "--out", str(out), "--seed", "4", "--quiet")
    assert proc.returncode == 130 and "disk full: 1 impacts kept" in proc.stdout, proc
    assert _status(out)[0] == "interrupted"
    assert _impacts(out) == 1  # the half-written impact is gone, the first one kept
    monkeypatch.setattr(writer, "_write_trace", real)
    assert labctl_here_json(capsys, "run", str(protocol), "--out", str(out), "--resume", "--quiet")["status"] == \
        "complete"
    _stored_vs_processed(capsys, out)


def test_a_world_law_failing_at_step_2_is_refused_before_a_file_is_made(protocol: Path, tmp_path: Path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text('[baseline]\nmodel = "expression"\nexpression = "3e5 * (110 - F)"\n', encoding="utf-8")
    out = tmp_path / "c.h5"
    proc = labctl_here(capsys, "run", str(protocol), "--out", str(out), "--world", str(bad), "--seed", "1",
                       "--quiet")
    assert proc.returncode == 2 and "bad.toml" in proc.stderr and "non-positive" in proc.stderr
    assert not out.exists()


def test_an_error_at_step_2_marks_the_file_failed_there_and_resume_completes(protocol: Path, tmp_path: Path,
                                                                              capsys, monkeypatch):
    import labctl.campaign as campaign
    from labctl.recording import process_step

    real_engine, calls = campaign._engine, []

    def faulty(*args, **kw):  # an unexpected error while identifying the second step
        calls.append(1)
        if len(calls) == 2:
            raise ValueError("simulated fault in step identification")
        return process_step(*args, **kw)

    def faulty_engine(*args, **kw):  # the engine's step pipeline (its identify_step) meets the fault
        engine = real_engine(*args, **kw)
        engine.identify_step = faulty
        return engine

    monkeypatch.setattr(campaign, "_engine", faulty_engine)
    out = tmp_path / "c.h5"
    proc = labctl_here(capsys, "run", str(protocol), "--out", str(out), "--seed", "1", "--quiet")
    assert proc.returncode == 2 and "simulated fault" in proc.stderr
    status, message = _status(out)
    assert status == "failed" and "step 2" in message and "--resume" in message
    monkeypatch.setattr(campaign, "_engine", real_engine)  # the cause fixed
    done = labctl_here_json(capsys, "run", str(protocol), "--out", str(out), "--resume", "--quiet")
    assert done["status"] == "complete" and [s for s, *_ in _plan(out)] == [1, 2, 3]


# 20 SIGKILLs at chosen write calls (inside HDF5's flush too), each campaign resumed to the steps and loads of an
# uninterrupted run: tests/test_crash_points.py (deterministic kill points, not timings).


def impacts_stored(reader) -> int:
    """Impacts in series 1 (read_live runs this in its reading child: module level, picklable)."""
    return sum(len(s.impacts) for run in reader.runs(1) for s in run.steps) if reader.series_indices() else 0


def test_a_running_campaign_is_reported_in_use_and_can_be_read_live(tmp_path: Path, capsys):
    """While `labctl run` writes, `process` names the writer (pid, since when); a live read sees the impacts
    stored so far, growing, and the writer finishes undisturbed."""
    import labctl.cli.process  # noqa: F401 — imported before the run starts, so the reads below are quick
    import labctl.reprocess  # noqa: F401
    from labctl.storage.inuse import writer_info
    from labctl.storage.live import read_live

    out, log = tmp_path / "c.h5", tmp_path / "log.txt"
    proc = FORK.Process(target=_child_stopped_after_first_impact,
                        args=(["run", "quick_check", "--out", str(out), "--seed", "2", "--quiet"], str(log)))
    proc.start()
    deadline = time.monotonic() + 60
    while not _stopped(proc.pid) and proc.is_alive() and time.monotonic() < deadline:
        time.sleep(0.005)  # the writer holds after its first impact (a poll for the file can miss a quick run)
    busy = labctl_here(capsys, "process", str(out))
    counts = []
    pacing = threading.Event()

    def pace() -> None:
        """The twin runs on virtual time (a quick_check takes well under a second): stop the writer 0.1 s in
        every 0.15 s so the reads below see it at several moments, as they would a run on the real rig."""
        while not pacing.is_set() and proc.is_alive():
            try:
                os.kill(proc.pid, signal.SIGSTOP)
                time.sleep(0.1)
                os.kill(proc.pid, signal.SIGCONT)
            except ProcessLookupError:  # the writer finished in between
                return
            time.sleep(0.05)

    pacer = threading.Thread(target=pace, daemon=True)
    pacer.start()
    try:
        while proc.is_alive() and time.monotonic() < deadline:
            counts.append(read_live(out, impacts_stored))
            time.sleep(0.01)
    finally:
        pacing.set()
        pacer.join()
        if proc.is_alive():
            os.kill(proc.pid, signal.SIGCONT)
    proc.join(60)
    assert proc.exitcode == 0, log.read_text()
    assert busy.returncode == 2 and f"pid {proc.pid}" in busy.stderr and "in use by" in busy.stderr, busy.stderr
    assert len(counts) >= 3 and counts == sorted(counts)  # read while running, never going back
    assert writer_info(out) is None  # the writer removed its sidecar
    assert labctl_here_json(capsys, "process", str(out))["status"] == "complete"


def test_a_link_that_fails_mid_walk_is_raised_after_the_walk_for_the_live_reader_to_retry(tmp_path: Path,
                                                                                           monkeypatch) -> None:
    """A running campaign can be caught half-way through writing a link: the error that meets must come out of
    the structure check as itself (a KeyError the live reader retries), not as a SystemError from inside HDF5's
    iteration (seen in a loaded run of the test above)."""
    import numpy as np

    import labctl.storage.safety as safety

    path = tmp_path / "f.h5"
    with h5py.File(path, "w") as f:
        f.create_dataset("series_001/a", data=np.zeros(3))
    real = safety.h5o.open

    def torn(loc: object, name: bytes) -> object:
        if name == b"series_001/a":
            raise KeyError("half-written")
        return real(loc, name)

    monkeypatch.setattr(safety.h5o, "open", torn)
    with h5py.File(path, "r") as f, pytest.raises(KeyError, match="half-written"):
        safety.check_structure(f)


def _child_stopped_after_first_impact(argv: list[str], log: str) -> None:
    """`labctl run` that stops itself (SIGSTOP) once its first impact is written, for the parent to signal."""
    from labctl.storage.writer import CampaignWriter

    write, written = CampaignWriter.write_impact, []

    def write_then_stop(self, *args, **kwargs):  # noqa: ANN001, ANN002, ANN003, ANN202
        record = write(self, *args, **kwargs)
        if not written:
            written.append(record)
            os.kill(os.getpid(), signal.SIGSTOP)
        return record

    CampaignWriter.write_impact = write_then_stop
    _child(argv, None, log)


def _stopped(pid: int) -> bool:
    """The process is stopped (state T in /proc)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] == "T"
    except OSError:
        return False


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_end_the_run_interrupted_and_resumable(sig: int, protocol: Path, tmp_path: Path,
                                                                   capsys):
    """A service stop (SIGTERM) or a dropped SSH session (SIGHUP) while the run writes: the run stops after the
    current impact, the file says `interrupted` with the resume hint (not `running`), reads, and resumes."""
    from labctl.storage.inuse import writer_info

    out, log = tmp_path / "c.h5", tmp_path / "log.txt"
    proc = FORK.Process(target=_child_stopped_after_first_impact,
                        args=(["run", str(protocol), "--out", str(out), "--seed", "4"], str(log)))
    proc.start()
    deadline = time.monotonic() + 60
    while not _stopped(proc.pid) and proc.is_alive() and time.monotonic() < deadline:
        time.sleep(0.005)  # (polling for the file instead missed the whole run on a loaded machine, 1 in 10)
    assert writer_info(out) is not None  # the signal arrives while the campaign is open for writing
    os.kill(proc.pid, sig)
    os.kill(proc.pid, signal.SIGCONT)
    proc.join(60)
    text = log.read_text()
    assert proc.exitcode == 130, text
    assert "Traceback" not in text
    status, message = _status(out)
    assert status == "interrupted" and "--resume" in message, (status, message)
    assert _impacts(out) < 6  # stopped early (the file was read above: it opens)
    done = labctl_here_json(capsys, "run", str(protocol), "--out", str(out), "--resume", "--quiet")
    assert done["status"] == "complete"
    _stored_vs_processed(capsys, out)


def _child_signalled_in_setup(argv: list[str], log: str) -> None:
    """`labctl run` that receives SIGTERM right after its file is created, while the rig is still being set up."""
    import labctl.campaign as campaign

    build = campaign._engine

    def engine_then_sigterm(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        os.kill(os.getpid(), signal.SIGTERM)  # the handler, if installed, only asks for a stop
        return build(*args, **kwargs)

    campaign._engine = engine_then_sigterm
    _child(argv, None, log)


def test_a_sigterm_while_the_run_is_set_up_still_ends_interrupted(protocol: Path, tmp_path: Path, capsys):
    """The stop handlers are in place before the file is created: a SIGTERM between creating the file and the
    first impact ends `interrupted` (it killed the process and left `running` when they came only with the run)."""
    out, log = tmp_path / "c.h5", tmp_path / "log.txt"
    proc = FORK.Process(target=_child_signalled_in_setup,
                        args=(["run", str(protocol), "--out", str(out), "--seed", "4"], str(log)))
    proc.start()
    proc.join(60)
    assert proc.exitcode == 130, log.read_text()
    status, message = _status(out)
    assert status == "interrupted" and "--resume" in message, (status, message)
    assert _impacts(out) == 0
    done = labctl_here_json(capsys, "run", str(protocol), "--out", str(out), "--resume", "--quiet")
    assert done["status"] == "complete"
